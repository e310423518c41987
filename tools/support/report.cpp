// The extraction report and summary line.
#include "tools/support/report.h"

#include <algorithm>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <string_view>

#include "io/file/atomic_file.h"
#include "tools/support/stats_fields.h"

namespace isotope::tools {

namespace {

// A visitor of the stats' field walks that puts each field into J under its name.
auto put_into(nlohmann::ordered_json& j) {
  return [&j](const char* name, const auto& value) { j[name] = value; };
}

constexpr ChangeKind kChangeKinds[] = {ChangeKind::lost,           ChangeKind::appeared,     ChangeKind::merged,
                                       ChangeKind::split,          ChangeKind::rearranged,   ChangeKind::handles_closed,
                                       ChangeKind::handles_opened, ChangeKind::euler_changed};

int64_t count_of(const ComponentComparison& c, ChangeKind k) {
  return std::count_if(c.changes.begin(), c.changes.end(), [k](const ComponentChange& ch) { return ch.kind == k; });
}

nlohmann::ordered_json component_json(const ComponentStats& c) {
  nlohmann::ordered_json j;
  j["triangles"] = c.triangles;
  j["vertices"] = c.vertices;
  j["euler_characteristic"] = c.euler_characteristic;
  j["closed"] = c.closed;
  j["genus"] = c.genus ? nlohmann::ordered_json(*c.genus) : nlohmann::ordered_json(nullptr);
  j["bbox_min"] = c.bbox_min;
  j["bbox_max"] = c.bbox_max;
  j["area"] = c.area;
  j["volume"] = c.volume ? nlohmann::ordered_json(*c.volume) : nlohmann::ordered_json(nullptr);
  if (c.closed) j["encloses"] = c.encloses_inside ? "inside" : "outside";
  return j;
}

nlohmann::ordered_json components_json(const std::vector<ComponentStats>& components) {
  nlohmann::ordered_json list = nlohmann::ordered_json::array();
  for (const ComponentStats& c : components) list.push_back(component_json(c));
  return list;
}

// What the adaptive mesh did to the full-resolution surface, group by group.
nlohmann::ordered_json comparison_json(const ComponentComparison& c, double tolerance, double seconds) {
  nlohmann::ordered_json j;
  int64_t triangles = 0, euler = 0;
  for (const ComponentStats& s : c.full_components) triangles += s.triangles, euler += s.euler_characteristic;
  j["full"] = {{"triangles", triangles}, {"components", c.full_components.size()}, {"euler_characteristic", euler}};
  nlohmann::ordered_json counts;
  for (ChangeKind k : kChangeKinds) counts[std::string(to_string(k))] = count_of(c, k);
  counts["unchanged"] = c.matched_unchanged.size();
  j["summary"] = counts;
  nlohmann::ordered_json changes = nlohmann::ordered_json::array();
  for (const ComponentChange& ch : c.changes)
    changes.push_back({{"kind", std::string(to_string(ch.kind))},
                       {"full", ch.full},
                       {"adaptive", ch.adaptive},
                       {"genus_change", ch.genus_change},
                       {"euler_change", ch.euler_change}});
  j["changes"] = changes;
  j["match_tolerance"] = tolerance;
  j["seconds"] = seconds;
  j["samples_matched"] = {{"full", c.full_samples_matched},
                          {"full_of", c.full_samples},
                          {"adaptive", c.adaptive_samples_matched},
                          {"adaptive_of", c.adaptive_samples}};
  j["full_components"] = components_json(c.full_components);
  return j;
}

}  // namespace

std::string comparison_line(const ComponentComparison& c) {
  std::string line = "against full resolution (" + std::to_string(c.full_components.size()) + " components): ";
  bool any = false;
  for (ChangeKind k : kChangeKinds) {
    const int64_t n = count_of(c, k);
    if (n == 0) continue;
    line += (any ? ", " : "") + std::to_string(n) + " " + std::string(to_string(k));
    any = true;
  }
  return line + (any ? "" : "no change") + "; " + std::to_string(c.matched_unchanged.size()) + " unchanged";
}

void describe(const SourceInfo& info, ExtractionRun& run) {
  run.data_dims = info.dims;
  run.spacing = info.spacing;
  run.lattice_k = info.lattice_k;
  run.read_seconds = info.read_seconds;
  run.preprocess_seconds = info.preprocess_seconds;
  run.input_bytes = info.input_bytes;
  run.hierarchy_built = info.hierarchy_built;
  run.critical_counted = info.critical_counted;
  for (int t = 0; t < 3; ++t) {
    run.preprocess.critical_paper[t] = info.critical_paper[t];
    run.preprocess.critical_exact[t] = info.critical_exact[t];
  }
  run.preprocess.seconds = info.preprocess_seconds;
  // A store's cache, or the cache of the store a volume's hierarchy was converted into.
  if (info.cache_mb == 0) return;
  run.cache = {.bricks_read = info.bricks_read,
               .bytes_read = info.bytes_read,
               .hits = info.cache_hits,
               .peak_bytes = info.cache_peak_bytes,
               .read_waits = info.read_waits,
               .read_hints = info.read_hints};
  run.cache_mb = info.cache_mb;
  run.cache_budget_bytes = info.cache_budget_bytes;
  run.cache_brick_bytes = info.cache_brick_bytes;
  run.store_bytes = info.store_bytes;
}

namespace {

// A distributed run's balance: the largest rank's share over the mean (1 is perfect).
template <class Field>
double max_over_mean(const std::vector<RankLoad>& loads, Field field) {
  double sum = 0, most = 0;
  for (const RankLoad& l : loads) {
    const auto v = static_cast<double>(field(l));
    sum += v;
    most = std::max(most, v);
  }
  return sum > 0 ? most * static_cast<double>(loads.size()) / sum : 1.0;
}

struct Balance {
  double cost, work, bytes, seconds;
};
Balance balance_of(const std::vector<RankLoad>& loads) {
  return {max_over_mean(loads, [](const RankLoad& l) { return l.cost; }),
          max_over_mean(loads, [](const RankLoad& l) { return l.work; }),
          max_over_mean(loads, [](const RankLoad& l) { return l.bytes_read; }),
          max_over_mean(loads, [](const RankLoad& l) { return l.seconds; })};
}

}  // namespace

nlohmann::ordered_json report_json(const ExtractionRun& run) {
  const MeshTopology& t = run.topology;
  nlohmann::ordered_json j;
  j["triangles"] = t.triangles;
  j["vertices"] = t.vertices;
  j["edges"] = t.edges;
  j["components"] = t.components;
  j["euler_characteristic"] = t.euler_characteristic;
  j["boundary_edges"] = t.boundary_edges;
  j["nonmanifold_edges"] = t.nonmanifold_edges;
  j["seconds"] = run.total_seconds();
  j["threads"] = run.threads;
  j["peak_rss_mb"] = run.peak_rss_mb;
  // A volume's extraction reads its values (its hierarchy's store, if any, is in the cache block).
  j["bytes_read"] = run.input_bytes > 0 ? run.input_bytes : run.cache.bytes_read;
  j["bricks_read"] = run.cache.bricks_read;
  j["cache_hits"] = run.cache.hits;

  j["input"] = run.input;
  j["output"] = run.output;
  j["iso"] = run.options.iso;
  j["eps"] = run.options.eps;
  if (run.options.eps_ties >= 0) j["eps_ties"] = run.options.eps_ties;
  j["error"] = std::string(to_string(run.options.error));
  j["topology"] = std::string(to_string(run.options.topology));
  if (run.options.topology == TopologyMode::simplify) {
    j["weight"] = std::string(to_string(run.options.weight));
    j["delta"] = run.options.delta;
  }
  if (run.options.focus) {
    j["focus"] = run.options.focus->point;
    j["radius"] = run.options.focus->radius;
  }
  if (run.options.max_triangles > 0) {
    j["max_triangles"] = run.options.max_triangles;
    for_each_budget_stat(run.extract, put_into(j));
  }
  if (run.extract.chosen_delta >= 0) {
    for_each_delta_stat(run.extract, put_into(j));
    j["tets_dropped"] = run.extract.tets_simplified;
  }
  j["data_dims"] = run.data_dims;
  j["lattice_k"] = run.lattice_k;
  j["lattice_side"] = (int64_t{1} << run.lattice_k) + 1;

  j["read_seconds"] = run.read_seconds;
  j["preprocess_seconds"] = run.preprocess_seconds;
  j["extract_seconds"] = run.extract_seconds;
  j["measure_seconds"] = run.measure_seconds;

  const PreprocessStats& p = run.preprocess;
  if (!run.hierarchy_built)
    j["preprocess"] = nullptr;
  else {
    // Per diamond type; null where nobody counted them.
    auto counts = [&](const int64_t(&c)[3]) -> nlohmann::ordered_json {
      if (!run.critical_counted) return nullptr;
      return {{"cube", c[0]}, {"octahedron", c[1]}, {"diamond", c[2]}};
    };
    j["preprocess"] = {
        {"seconds", p.seconds},
        {"critical_paper", counts(p.critical_paper)},
        {"critical_exact", counts(p.critical_exact)},
    };
  }
  nlohmann::ordered_json work = nlohmann::ordered_json::object();
  for_each_work_stat(run.extract, put_into(work));
  j["extract"] = std::move(work);
  if (!run.extract.ranks.empty()) {
    nlohmann::ordered_json ranks = nlohmann::ordered_json::array();
    for (const RankLoad& l : run.extract.ranks) {
      nlohmann::ordered_json load = nlohmann::ordered_json::object();
      for_each_load_stat(l, put_into(load));
      ranks.push_back(std::move(load));
    }
    const Balance b = balance_of(run.extract.ranks);
    j["ranks"] = ranks;
    j["balance"] = {{"cost_max_over_mean", b.cost},
                    {"work_max_over_mean", b.work},
                    {"bytes_read_max_over_mean", b.bytes},
                    {"seconds_max_over_mean", b.seconds}};
  }
  j["per_component"] = components_json(run.components);
  if (run.comparison) j["compare_full"] = comparison_json(*run.comparison, run.compare_tolerance, run.compare_seconds);
  if (run.cache_mb > 0)
    j["cache"] = {{"budget_mb", run.cache_mb},
                  {"effective_budget_mb", static_cast<double>(run.cache_budget_bytes) / (1 << 20)},
                  {"brick_mb", static_cast<double>(run.cache_brick_bytes) / (1 << 20)},
                  {"peak_decoded_mb", static_cast<double>(run.cache.peak_bytes) / (1 << 20)},
                  {"store_bytes", run.store_bytes},
                  {"bytes_read", run.cache.bytes_read},
                  {"read_waits", run.cache.read_waits},
                  {"read_hints", run.cache.read_hints}};
  return j;
}

namespace {
// A stage's seconds to four significant digits, not to the millisecond: a small volume's
// extraction takes a few milliseconds, where one step of the last digit was 15-20% of it. From
// 1,000 s on, whole seconds.
std::string stage_seconds(double seconds) {
  char b[32];
  std::snprintf(b, sizeof b, seconds < 1000 ? "%#.4g" : "%.0f", seconds);
  return b;
}
}  // namespace

std::string summary_line(const ExtractionRun& run) {
  const MeshTopology& t = run.topology;
  std::string chosen = run.options.max_triangles > 0 ? "; eps " + std::to_string(run.extract.chosen_eps) : "";
  if (run.options.max_triangles > 0 && run.extract.chosen_eps_ties >= 0)
    chosen += ", eps-ties " + std::to_string(run.extract.chosen_eps_ties);
  if (run.extract.chosen_delta >= 0) chosen += ", delta " + std::to_string(run.extract.chosen_delta);
  char buf[640];
  std::snprintf(buf, sizeof buf,
                "%s: %lld triangles, %lld vertices, %lld component%s, chi %lld, %lld boundary / %lld "
                "non-manifold edges; preprocess %s s, extract %s s%s",
                run.output.c_str(), static_cast<long long>(t.triangles), static_cast<long long>(t.vertices),
                static_cast<long long>(t.components), t.components == 1 ? "" : "s",
                static_cast<long long>(t.euler_characteristic), static_cast<long long>(t.boundary_edges),
                static_cast<long long>(t.nonmanifold_edges), stage_seconds(run.preprocess_seconds).c_str(),
                stage_seconds(run.extract_seconds).c_str(), chosen.c_str());
  return buf + balance_text(run.extract.ranks);
}

std::string balance_text(const std::vector<RankLoad>& loads) {
  if (loads.empty()) return {};
  const Balance b = balance_of(loads);
  char buf[160];
  std::snprintf(buf, sizeof buf, "; %zu ranks, max/mean: cost %.2f, work %.2f, bytes read %.2f, time %.2f",
                loads.size(), b.cost, b.work, b.bytes, b.seconds);
  return buf;
}

void write_json_file(const nlohmann::ordered_json& json, const std::string& path) {
  const std::string text = json.dump(2) + "\n";
  AtomicFile file(path);
  file.write(text.data(), text.size());
  file.commit();
}

}  // namespace isotope::tools
