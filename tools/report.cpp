// The extraction report and summary line (tools/report.h).
#include "tools/report.h"

#include <cstdio>
#include <nlohmann/json.hpp>
#include <string_view>

#include "io/atomic_file.h"

namespace isotope::tools {

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
  j["bytes_read"] = run.cache_mb > 0 ? run.cache.bytes_read : run.input_bytes;
  j["bricks_read"] = run.cache.bricks_read;
  j["cache_hits"] = run.cache.hits;

  j["input"] = run.input;
  j["output"] = run.output;
  j["iso"] = run.options.iso;
  j["eps"] = run.options.eps;
  j["error"] = std::string(to_string(run.options.error));
  j["topology"] = std::string(to_string(run.options.topology));
  if (run.options.focus) {
    j["focus"] = run.options.focus->point;
    j["radius"] = run.options.focus->radius;
  }
  if (run.options.max_triangles > 0) {
    j["max_triangles"] = run.options.max_triangles;
    j["chosen_eps"] = run.extract.chosen_eps;
    j["next_eps"] = run.extract.next_eps;
    j["next_triangles"] = run.extract.next_triangles;
  }
  j["data_dims"] = run.data_dims;
  j["lattice_k"] = run.lattice_k;
  j["lattice_side"] = (int64_t{1} << run.lattice_k) + 1;

  j["read_seconds"] = run.read_seconds;
  j["preprocess_seconds"] = run.preprocess_seconds;
  j["extract_seconds"] = run.extract_seconds;
  j["measure_seconds"] = run.measure_seconds;

  const PreprocessStats& p = run.preprocess;
  j["preprocess"] = {
      {"seconds", p.seconds},
      {"critical_paper", {{"cube", p.critical_paper[0]}, {"octahedron", p.critical_paper[1]}, {"diamond", p.critical_paper[2]}}},
      {"critical_exact", {{"cube", p.critical_exact[0]}, {"octahedron", p.critical_exact[1]}, {"diamond", p.critical_exact[2]}}},
  };
  j["extract"] = {
      {"seconds", run.extract.seconds},
      {"tets_visited", run.extract.tets_visited},
      {"tets_emitted", run.extract.tets_emitted},
  };
  if (run.cache_mb > 0)
    j["cache"] = {{"budget_mb", run.cache_mb},
                  {"effective_budget_mb", static_cast<double>(run.cache_budget_bytes) / (1 << 20)},
                  {"peak_decoded_mb", static_cast<double>(run.cache.peak_bytes) / (1 << 20)},
                  {"store_bytes", run.store_bytes}};
  return j;
}

std::string summary_line(const ExtractionRun& run) {
  const MeshTopology& t = run.topology;
  const std::string chosen = run.options.max_triangles > 0 ? "; eps " + std::to_string(run.extract.chosen_eps) : "";
  char buf[640];
  std::snprintf(buf, sizeof buf,
                "%s: %lld triangles, %lld vertices, %lld component%s, chi %lld, %lld boundary / %lld "
                "non-manifold edges; preprocess %.3f s, extract %.3f s%s",
                run.output.c_str(), static_cast<long long>(t.triangles), static_cast<long long>(t.vertices),
                static_cast<long long>(t.components), t.components == 1 ? "" : "s",
                static_cast<long long>(t.euler_characteristic), static_cast<long long>(t.boundary_edges),
                static_cast<long long>(t.nonmanifold_edges), run.preprocess_seconds, run.extract_seconds,
                chosen.c_str());
  return buf;
}

void write_json_file(const nlohmann::ordered_json& json, const std::string& path) {
  const std::string text = json.dump(2) + "\n";
  AtomicFile file(path);
  file.write(text.data(), text.size());
  file.commit();
}

}  // namespace isotope::tools
