// isotope sweep: one table (and optionally a CSV and a PNG plot) of what eps, the topology mode
// and delta do to one isosurface: triangles, components, Euler characteristic and time for every
// combination, so that a user sees the trade-off before choosing.
#include <oneapi/tbb/global_control.h>

#include <CLI/CLI.hpp>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "engine/extract/extract_drivers.h"
#include "io/file/atomic_file.h"
#include "isotope/mesh.h"
#include "isotope/source.h"
#include "tools/commands.h"
#include "tools/support/line_plot.h"

namespace isotope::tools {
namespace {

struct SweepArgs {
  std::string input;
  std::string iso;
  std::string eps = "0,1/64,1/16,1/4,1";
  std::string delta = "0";
  std::string weight = "interval";
  std::string csv;
  std::string plot;
  int threads = 0;
  int64_t cache_mb = OpenOptions{}.cache_mb;
  bool quiet = false;
};

struct SweepRow {
  TopologyMode mode = TopologyMode::none;
  double delta = 0, eps = 0;
  MeshTopology topology;
  double seconds = 0;
};

// A comma-separated list of one extraction option's values, each read by the reader every face
// shares (option_text).
std::vector<double> parse_list(const std::string& text, const std::string& name) {
  std::vector<double> values;
  std::stringstream in(text);
  for (std::string item; std::getline(in, item, ',');) {
    ExtractOptions o;
    try {
      set_extract_option(o, name, item);
    } catch (const OptionError& e) {
      throw CLI::ValidationError("--" + name, "must be a comma-separated list of numbers >= 0: " + e.message);
    }
    values.push_back(name == "eps" ? o.eps : o.delta);
  }
  if (values.empty()) throw CLI::ValidationError("--" + name, "must list at least one number");
  return values;
}

std::string mode_label(const SweepRow& r) {
  std::string s(to_string(r.mode));
  if (r.mode == TopologyMode::simplify) {
    char d[32];
    std::snprintf(d, sizeof d, " delta=%g", r.delta);
    s += d;
  }
  return s;
}

void print_table(const std::vector<SweepRow>& rows, const std::string& weight) {
  std::printf("%-24s %12s %12s %11s %7s %10s\n", ("mode (weight " + weight + ")").c_str(), "eps", "triangles",
              "components", "euler", "seconds");
  for (const SweepRow& r : rows)
    std::printf("%-24s %12g %12lld %11lld %7lld %10.4f\n", mode_label(r).c_str(), r.eps,
                static_cast<long long>(r.topology.triangles), static_cast<long long>(r.topology.components),
                static_cast<long long>(r.topology.euler_characteristic), r.seconds);
}

void write_csv(const std::vector<SweepRow>& rows, const std::string& weight, const std::string& path) {
  std::string text = "mode,weight,delta,eps,triangles,components,euler_characteristic,seconds\n";
  char line[256];
  for (const SweepRow& r : rows) {
    std::snprintf(line, sizeof line, "%s,%s,%.10g,%.10g,%lld,%lld,%lld,%.6f\n", std::string(to_string(r.mode)).c_str(),
                  r.mode == TopologyMode::simplify ? weight.c_str() : "", r.delta, r.eps,
                  static_cast<long long>(r.topology.triangles), static_cast<long long>(r.topology.components),
                  static_cast<long long>(r.topology.euler_characteristic), r.seconds);
    text += line;
  }
  AtomicFile file(path);
  file.write(text.data(), text.size());
  file.commit();
}

// Triangles against eps, one line per mode and delta.
void write_plot(const std::vector<SweepRow>& rows, const std::string& iso, const std::string& weight,
                const std::string& path) {
  LinePlot plot;
  plot.title = "iso " + iso + ": triangles against eps (simplify weight " + weight + ")";
  plot.x_label = "eps";
  for (const SweepRow& r : rows)
    if (r.eps == 0) {  // a log axis has no 0: name the full-resolution count instead
      plot.x_label += "   (eps 0, full resolution: " + std::to_string(r.topology.triangles) + " triangles)";
      break;
    }
  plot.y_label = "triangles";
  plot.log_x = plot.log_y = true;
  for (const SweepRow& r : rows) {
    const std::string label = mode_label(r);
    if (plot.series.empty() || plot.series.back().label != label) plot.series.push_back({label, {}, {}});
    plot.series.back().x.push_back(r.eps);
    plot.series.back().y.push_back(static_cast<double>(r.topology.triangles));
  }
  write_line_plot_png(plot, path);
}

int run_sweep(const SweepArgs& a) {
  const bool progress = progress_enabled(a.quiet);
  const std::vector<double> eps = parse_list(a.eps, "eps"), deltas = parse_list(a.delta, "delta");
  // The weight is read as simplify's, the mode whose rows use it.
  ExtractOptions base = parse_command_line_options({{"iso", a.iso}, {"topology", "simplify"}, {"weight", a.weight}});
  // Output paths are checked (and the files' temporaries created) only at the end; check the
  // directories now so that a long sweep does not fail at its last step.
  check_outputs({{"INPUT", a.input}}, {{"--csv", a.csv}, {"--plot", a.plot}});
  for (const std::string* path : {&a.csv, &a.plot})
    if (!path->empty()) AtomicFile check(*path);

  std::optional<tbb::global_control> threads;
  if (a.threads > 0) threads.emplace(tbb::global_control::max_allowed_parallelism, static_cast<size_t>(a.threads));
  // A store is paged through one cache for the whole sweep (each brick is read once); any other
  // volume is preprocessed once.
  const Source source = open_input(a.input, "", "", a.cache_mb, progress);

  std::vector<SweepRow> plan;
  auto add_mode = [&](TopologyMode mode, double delta) {
    for (double e : eps) plan.push_back({mode, delta, e, {}, 0});
  };
  add_mode(TopologyMode::none, 0);
  add_mode(TopologyMode::preserve, 0);
  for (double d : deltas) add_mode(TopologyMode::simplify, d);
  std::vector<ExtractOptions> planned;
  for (const SweepRow& r : plan) {
    ExtractOptions o = base;
    o.topology = r.mode;
    o.eps = r.eps;
    planned.push_back(o);
  }
  const RunContext run = preprocessing_context(progress);
  source.prepare(planned, run);
  for (size_t i = 0; i < plan.size(); ++i) {
    SweepRow& r = plan[i];
    ExtractOptions o = base;
    o.topology = r.mode;
    o.eps = r.eps;
    o.delta = r.delta;
    ExtractStats stats;
    const Mesh mesh = source.extract(o, run, &stats);
    r.seconds = stats.seconds;
    r.topology = measure_topology(mesh);
    if (progress) std::fprintf(stderr, "\risotope: sweep %zu/%zu", i + 1, plan.size());
  }
  if (progress) std::fprintf(stderr, "\n");
  if (!a.quiet) print_table(plan, a.weight);
  if (!a.csv.empty()) write_csv(plan, a.weight, a.csv);
  if (!a.plot.empty()) write_plot(plan, a.iso, a.weight, a.plot);
  return 0;
}

}  // namespace

Command add_sweep_command(CLI::App& app) {
  auto a = std::make_shared<SweepArgs>();
  CLI::App* cmd = app.add_subcommand(
      "sweep", "Tabulate triangles, components, Euler characteristic and time over eps x topology mode x delta");
  cmd->add_option("INPUT", a->input, "Store made by 'isotope convert' (or any volume 'isotope extract' reads)")
      ->required();
  cmd->add_option("--iso", a->iso, "Isovalue (inside means value > iso)")
      ->required()
      ->check(extract_option_check("iso"))
      ->type_name("V");
  cmd->add_option("--eps", a->eps, "Error thresholds, comma-separated (fractions like 1/64 allowed)")
      ->type_name("LIST")
      ->capture_default_str();
  cmd->add_option("--delta", a->delta, "Simplification thresholds for --topology simplify, comma-separated")
      ->type_name("LIST")
      ->capture_default_str();
  cmd->add_option("--weight", a->weight, "Simplification weight: interval, gradient or size")
      ->check(extract_option_check("weight"))
      ->capture_default_str();
  cmd->add_option("--csv", a->csv, "Also write the table as CSV")->type_name("F.csv");
  cmd->add_option("--plot", a->plot, "Also plot triangles against eps per mode (PNG)")->type_name("F.png");
  cmd->add_option("--threads", a->threads, "Worker threads (0 = all cores)")
      ->check(thread_count_check())
      ->capture_default_str();
  cmd->add_option("--cache-mb", a->cache_mb,
                  "Memory for decoded bricks, in MB, of a store input or of a volume's hierarchy (a store of its own)")
      ->check(CLI::Range(int64_t{1}, int64_t{1} << 30))
      ->capture_default_str();
  cmd->add_flag("-q,--quiet", a->quiet, "Print nothing on success");
  return [a] { return run_sweep(*a); };
}

}  // namespace isotope::tools
