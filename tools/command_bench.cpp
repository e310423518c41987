// isotope bench: one command that times adaptive extraction on a fixed suite of volumes against
// the obvious alternative, full-resolution marching tetrahedra over the raw array, measured in the
// same run on one thread and on all of them; prints the paper's Table 1 beside the paper's numbers
// and VTK's Flying Edges times (measured on the development machine) beside ours.
#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <malloc.h>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <oneapi/tbb/global_control.h>
#include <optional>
#include <string>
#include <thread>
#include <unistd.h>
#include <vector>

#include "engine/extract.h"
#include "engine/fields.h"
#include "engine/multires_volume.h"
#include "io/atomic_file.h"
#include "io/box_reader.h"
#include "io/brick_cache.h"
#include "io/io_error.h"
#include "io/paged_volume.h"
#include "io/store_reader.h"
#include "io/store_writer.h"
#include "io/temp_dir.h"
#include "io/volume_box_reader.h"
#include "io/volume_reader.h"
#include "tools/commands.h"
#include "tools/extraction_input.h"
#include "tools/interrupt_guard.h"
#include "tools/paper_table1.h"
#include "tools/peak_memory.h"
#include "tools/report.h"

#ifndef ISOTOPE_SHARED_DATA
#define ISOTOPE_SHARED_DATA "../shared/data"
#endif
#ifndef ISOTOPE_VERSION
#define ISOTOPE_VERSION "unknown"
#endif

namespace isotope::tools {
namespace {

struct BenchArgs {
  bool quick = false;
  std::string json;
  int threads = 0;
  std::string data = ISOTOPE_SHARED_DATA;
  std::vector<std::string> datasets;
  std::string work_dir;
  int64_t cache_mb = 512;
  bool quiet = false;
};

// ---- The suite -------------------------------------------------------------------------------

struct DatasetSpec {
  const char* name;
  const char* description;
  const char* file;  // in --data; nullptr: generated
  float iso;
  bool quick;        // part of --quick
  // Also preprocess in memory (the raw-input path of isotope extract). The in-memory hierarchy of
  // a 513^3 volume would take about 6 GB and a minute; those volumes go through a store only.
  bool in_memory;
  Volume (*generate)();
};

const std::vector<DatasetSpec>& suite() {
  static const std::vector<DatasetSpec> s = {
      {"algebraic65", "paper's algebraic function, 65^3 (Table 1)", nullptr, 0.0f, true, true,
       [] { return generate_algebraic(65); }},
      {"algebraic257", "paper's algebraic function, 257^3", nullptr, 0.0f, true, true,
       [] { return generate_algebraic(257); }},
      {"bolt", "bolt 70x123x66 uint8 (CAD scan, plateaus)", "bolt_70x123x66_uint8.raw", 64.5f, true, true, nullptr},
      {"hydrogen", "hydrogen orbital 64^3 float32", "hydrogen_64x64x64_float32.raw", 0.05f, true, true, nullptr},
      {"ironProt", "iron protein 68^3 uint8", "ironProt_68x68x68_uint8.raw", 32.5f, true, true, nullptr},
      {"neghip", "neghip 66^3 uint8", "neghip_66x66x66_uint8.raw", 32.5f, true, true, nullptr},
      {"noise384", "smooth random field (24 Gaussian bumps), 384^3", nullptr, 0.0f, false, false,
       [] { return generate_noise(384, 384); }},
      {"noise513", "smooth random field (24 Gaussian bumps), 513^3", nullptr, 0.0f, false, false,
       [] { return generate_noise(513, 513); }},
      {"sphere512", "sphere of radius 0.6 in [-1,1]^3, 512^3", nullptr, 0.0f, false, false,
       [] { return generate_sphere(512); }},
  };
  return s;
}

// VTK 9.1's vtkFlyingEdges3D on the development machine (2 x 2.1 GHz): one thread, full
// resolution, wall time without loading. Quoted from issue 6; VTK is not installed here.
struct Reference {
  const char* dataset;  // ours, when the suite has the same volume
  const char* what;
  double ms;
  int64_t triangles;  // 0: not given
};
constexpr Reference kFlyingEdges[] = {
    {"embryo", "embryo 256^3, iso 64.5", 51, 937552},
    {"algebraic257", "algebraic 257^3, iso 0", 21, 0},
    {"sphere512", "sphere 512^3", 295, 0},
    {"noise384", "smooth noise 384^3", 291, 0},
};

// The paper's speed claim (Sec. 4.6, quoting its ref. [6]): extraction and drawing together.
constexpr double kPaperTrianglesPerSecondOne = 300000, kPaperTrianglesPerSecondMany = 800000;

constexpr double kCoarseShare = 0.10;      // the coarse eps keeps at most this share of the triangles
constexpr double kDeltaOfRange = 0.02;     // simplify's delta, as a share of the value range

// ---- Measuring -------------------------------------------------------------------------------

struct Policy {
  size_t min_runs = 3, max_runs = 50;
  double min_seconds = 1.0;  // keep repeating a fast case until it has run this long
};

struct Row {
  std::string dataset, input, mode;  // input: raw, memory, store (cold cache) or store-warm
  double eps = 0, delta = 0;
  int threads = 1;
  int64_t triangles = 0;
  double seconds = 0;  // median of `runs`
  int runs = 0;
  uint64_t peak_rss = 0, bytes_read = 0;
  double speedup = 0;  // baseline's median at the same thread count over ours
  double share = 0;    // triangles over the full-resolution mesh's
};

class ThreadCap {
 public:
  explicit ThreadCap(int threads) : control_(tbb::global_control::max_allowed_parallelism, static_cast<size_t>(threads)) {}

 private:
  tbb::global_control control_;
};

// Runs CASE (which returns its triangle count and adds to bytes_read) until the policy is met;
// ROW gets the median time, the runs, the last run's counts and the peak RSS over all runs.
void measure(const Policy& p, Row& row, const std::function<int64_t(uint64_t& bytes_read)>& run_case) {
  const ThreadCap cap(row.threads);
  malloc_trim(0);  // memory freed by earlier rows, kept by malloc for reuse, is not this row's
  reset_peak_rss();
  std::vector<double> times;
  double total = 0;
  while (times.size() < p.min_runs || (total < p.min_seconds && times.size() < p.max_runs)) {
    if (InterruptGuard::interrupted()) throw IoError("interrupted");
    uint64_t bytes = 0;
    const auto start = std::chrono::steady_clock::now();
    row.triangles = run_case(bytes);
    times.push_back(seconds_since(start));
    total += times.back();
    row.bytes_read = bytes;
  }
  std::sort(times.begin(), times.end());
  row.seconds = times[times.size() / 2];
  row.runs = static_cast<int>(times.size());
  row.peak_rss = peak_rss_bytes();
}

// ---- One dataset -----------------------------------------------------------------------------

struct DatasetResult {
  const DatasetSpec* spec = nullptr;
  std::array<int64_t, 3> dims{};
  double value_min = 0, value_max = 0;
  int64_t full_triangles = 0;
  double coarse_eps = 0, delta = 0;
  double preprocess_seconds = -1;  // in memory; -1: not done
  double convert_seconds = 0;
  uint64_t store_bytes = 0;
  int64_t voxels() const { return dims[0] * dims[1] * dims[2]; }
};

class Suite {
 public:
  Suite(const BenchArgs& a, std::filesystem::path work, bool progress)
      : a_(a), work_(std::move(work)), progress_(progress) {
    threads_ = a.threads > 0 ? a.threads : static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
    if (a.quick) policy_ = {3, 20, 0.2};
  }

  int threads() const { return threads_; }
  const Policy& policy() const { return policy_; }
  std::vector<Row>& rows() { return rows_; }
  std::vector<DatasetResult>& datasets() { return datasets_; }
  nlohmann::ordered_json& table1() { return table1_; }

  void run(const DatasetSpec& spec, const Volume& volume) {
    DatasetResult d;
    d.spec = &spec;
    d.dims = volume.dims;
    const auto [lo, hi] = std::minmax_element(volume.values.begin(), volume.values.end());
    d.value_min = *lo;
    d.value_max = *hi;
    d.delta = kDeltaOfRange * (d.value_max - d.value_min);
    const size_t first = rows_.size();
    baseline_seconds_.clear();
    baseline(spec, volume, d);
    std::optional<MultiresVolume> memory;
    if (spec.in_memory) {
      say(spec, "preprocessing in memory");
      const ThreadCap cap(threads_);
      const auto start = std::chrono::steady_clock::now();
      memory.emplace(MultiresVolume::build(volume));
      d.preprocess_seconds = seconds_since(start);
    }
    const std::string store = convert(spec, volume, d);
    const StoreReader reader(store);
    d.store_bytes = reader.file_bytes();
    std::filesystem::remove(store);  // the reader keeps it open: nothing is left behind, however the run ends
    d.coarse_eps = coarse_eps(reader, spec, d);

    if (memory) {
      adaptive_rows(spec, d, "memory", [&](const ExtractOptions& o, uint64_t&) {
        return static_cast<int64_t>(extract(*memory, o).triangles.size());
      });
      if (spec.name == std::string("algebraic65")) paper_table1(*memory);
      memory.reset();
    }
    store_rows(spec, d, reader);
    const auto full = static_cast<double>(std::max<int64_t>(1, d.full_triangles));
    for (size_t i = first; i < rows_.size(); ++i) rows_[i].share = static_cast<double>(rows_[i].triangles) / full;
    datasets_.push_back(d);
  }

 private:
  void say(const DatasetSpec& spec, const char* what) const {
    if (progress_) std::fprintf(stderr, "\r\033[Kisotope: bench %s: %s", spec.name, what);
  }

  Row row(const DatasetSpec& spec, const char* input, const char* mode, double eps, int threads) const {
    Row r;
    r.dataset = spec.name;
    r.input = input;
    r.mode = mode;
    r.eps = eps;
    r.threads = threads;
    return r;
  }

  // Full-resolution marching tetrahedra over the array: the yardstick of every other row.
  void baseline(const DatasetSpec& spec, const Volume& volume, DatasetResult& d) {
    say(spec, "baseline");
    for (const int t : thread_counts()) {
      Row r = row(spec, "raw", "baseline", 0, t);
      measure(policy_, r, [&](uint64_t&) {
        return static_cast<int64_t>(extract_full_resolution(volume, spec.iso).triangles.size());
      });
      r.speedup = 1;
      d.full_triangles = r.triangles;
      baseline_seconds_[t] = r.seconds;
      rows_.push_back(r);
    }
  }

  std::vector<int> thread_counts() const { return threads_ > 1 ? std::vector<int>{1, threads_} : std::vector<int>{1}; }

  // The store the product's out-of-core path reads: shared volumes converted from their files
  // (integer data stays integer), generated ones from memory.
  std::string convert(const DatasetSpec& spec, const Volume& volume, DatasetResult& d) const {
    say(spec, "converting to a store");
    const std::string path = (work_ / (std::string(spec.name) + ".isotope")).string();
    std::unique_ptr<BoxReader> reader;
    if (spec.file)
      reader = open_box_reader({(std::filesystem::path(a_.data) / spec.file).string(), std::nullopt, std::nullopt},
                               work_.string());
    else
      reader = std::make_unique<VolumeBoxReader>(volume);
    const ThreadCap cap(threads_);
    ConvertOptions options;
    options.cancel = &InterruptGuard::flag();
    d.convert_seconds = convert_to_store(*reader, path, options).seconds;
    return path;
  }

  // The finest eps whose mesh without topology control has at most 10% of the full triangles
  // (the triangle budget's search, untimed); every coarse row uses it, whatever its mode.
  double coarse_eps(const StoreReader& reader, const DatasetSpec& spec, const DatasetResult& d) const {
    say(spec, "choosing the coarse eps");
    BrickCache cache(reader, cache_bytes());
    const PagedVolume volume(cache);
    ExtractOptions o;
    o.iso = spec.iso;
    o.topology = TopologyMode::none;
    o.max_triangles = std::max<int64_t>(1, static_cast<int64_t>(kCoarseShare * static_cast<double>(d.full_triangles)));
    ExtractStats stats;
    extract(volume, o, &stats);
    return stats.chosen_eps;
  }

  uint64_t cache_bytes() const { return static_cast<uint64_t>(a_.cache_mb) << 20; }

  ExtractOptions options(const DatasetSpec& spec, TopologyMode mode, double eps, double delta) const {
    ExtractOptions o;
    o.iso = spec.iso;
    o.eps = eps;
    o.topology = mode;
    o.delta = mode == TopologyMode::simplify ? delta : 0.0;
    return o;
  }

  // eps 0 and the coarse eps, on one thread and on all, for each topology mode.
  using Extraction = std::function<int64_t(const ExtractOptions&, uint64_t& bytes_read)>;
  void adaptive_rows(const DatasetSpec& spec, const DatasetResult& d, const char* input, const Extraction& run) {
    struct Case {
      TopologyMode mode;
      bool coarse;
      int threads;
    };
    const int n = threads_;
    std::vector<Case> cases = {{TopologyMode::preserve, false, 1}};
    if (n > 1) cases.push_back({TopologyMode::preserve, false, n});
    cases.push_back({TopologyMode::none, true, n});
    cases.push_back({TopologyMode::preserve, true, 1});
    if (n > 1) cases.push_back({TopologyMode::preserve, true, n});
    cases.push_back({TopologyMode::simplify, true, n});
    for (const Case& c : cases) {
      say(spec, std::string(to_string(c.mode)).c_str());
      const double eps = c.coarse ? d.coarse_eps : 0.0;
      const ExtractOptions o = options(spec, c.mode, eps, d.delta);
      Row r = row(spec, input, std::string(to_string(c.mode)).c_str(), eps, c.threads);
      r.delta = o.delta;
      measure(policy_, r, [&](uint64_t& bytes) { return run(o, bytes); });
      finish(r);
    }
  }

  void finish(Row& r) {
    r.speedup = baseline_seconds_.at(r.threads) / r.seconds;
    rows_.push_back(r);
  }

  // Out of core: a fresh cache per run (cold: every brick read and decoded; the store file itself
  // is in the OS page cache), then one cache kept across runs (warm: an interactive session).
  void store_rows(const DatasetSpec& spec, const DatasetResult& d, const StoreReader& reader) {
    const Extraction cold = [&](const ExtractOptions& o, uint64_t& bytes) {
      BrickCache cache(reader, cache_bytes());
      const PagedVolume volume(cache);
      const int64_t triangles = static_cast<int64_t>(extract(volume, o).triangles.size());
      bytes += cache.stats().bytes_read;
      return triangles;
    };
    if (!spec.in_memory) {
      adaptive_rows(spec, d, "store", cold);
    } else {
      for (const bool coarse : {false, true}) {
        say(spec, "store");
        const double eps = coarse ? d.coarse_eps : 0.0;
        const ExtractOptions o = options(spec, TopologyMode::preserve, eps, 0);
        Row r = row(spec, "store", "preserve", eps, threads_);
        measure(policy_, r, [&](uint64_t& bytes) { return cold(o, bytes); });
        finish(r);
      }
    }
    say(spec, "store, warm cache");
    BrickCache cache(reader, cache_bytes());
    const PagedVolume volume(cache);
    const ExtractOptions o = options(spec, TopologyMode::preserve, d.coarse_eps, 0);
    extract(volume, o);  // warms the cache
    Row r = row(spec, "store-warm", "preserve", d.coarse_eps, threads_);
    measure(policy_, r, [&](uint64_t& bytes) {
      const uint64_t before = cache.stats().bytes_read;
      const int64_t triangles = static_cast<int64_t>(extract(volume, o).triangles.size());
      bytes += cache.stats().bytes_read - before;
      return triangles;
    });
    finish(r);
  }

  // The paper's Table 1 on the same hierarchy: triangles per eps without and with topology
  // preservation, and our time for each on one thread.
  void paper_table1(const MultiresVolume& mv) {
    for (size_t i = 0; i < std::size(kTable1Eps); ++i) {
      nlohmann::ordered_json j;
      j["eps"] = kTable1Eps[i].label;
      j["paper"] = {{"without", kTable1Paper[i].without}, {"with", kTable1Paper[i].with}};
      for (const TopologyMode mode : {TopologyMode::none, TopologyMode::preserve}) {
        ExtractOptions o;
        o.iso = 0;
        o.eps = kTable1Eps[i].value;
        o.topology = mode;
        Row r;
        r.threads = 1;
        measure(policy_, r, [&](uint64_t&) { return static_cast<int64_t>(extract(mv, o).triangles.size()); });
        j[mode == TopologyMode::none ? "without" : "with"] = {{"triangles", r.triangles}, {"seconds", r.seconds}};
      }
      table1_.push_back(j);
    }
  }

  const BenchArgs& a_;
  std::filesystem::path work_;
  bool progress_;
  int threads_ = 1;
  Policy policy_;
  std::map<int, double> baseline_seconds_;
  std::vector<Row> rows_;
  std::vector<DatasetResult> datasets_;
  nlohmann::ordered_json table1_ = nlohmann::ordered_json::array();
};


// ---- Printing --------------------------------------------------------------------------------

std::string si(double v) {  // 3 significant digits with k / M / G
  const char* unit = "";
  for (const char* u : {"k", "M", "G"}) {
    if (v < 1000) break;
    v /= 1000;
    unit = u;
  }
  char b[32];
  std::snprintf(b, sizeof b, v < 10 ? "%.2f%s" : v < 100 ? "%.1f%s" : "%.0f%s", v, unit);
  return b;
}

std::string mb(uint64_t bytes) {
  char b[32];
  std::snprintf(b, sizeof b, "%.1f", static_cast<double>(bytes) / 1e6);
  return b;
}

std::string ms(double seconds) {
  char b[32];
  const double m = seconds * 1e3;
  std::snprintf(b, sizeof b, m < 10 ? "%.2f" : m < 100 ? "%.1f" : "%.0f", m);
  return b;
}

std::string mode_label(const Row& r) {
  if (r.mode != "simplify") return r.mode;
  char b[48];
  std::snprintf(b, sizeof b, "simplify %.3g", r.delta);
  return b;
}

void print_preprocessing(const std::vector<DatasetResult>& ds) {
  std::printf("\nDatasets (preprocessing on all threads; coarse eps: the finest eps whose 'none' mesh has at most %.0f%%\n"
              "of the full triangles; simplify: interval weight, delta = %.0f%% of the value range)\n",
              kCoarseShare * 100, kDeltaOfRange * 100);
  std::printf("%-13s %-12s %8s %12s %11s %10s %12s %9s %10s %9s\n", "dataset", "dims", "iso", "triangles", "in memory s",
              "convert s", "conv vox/s", "store MB", "coarse eps", "delta");
  for (const DatasetResult& d : ds) {
    const std::string dims = std::to_string(d.dims[0]) + "x" + std::to_string(d.dims[1]) + "x" + std::to_string(d.dims[2]);
    char pre[32] = "-";
    if (d.preprocess_seconds >= 0) std::snprintf(pre, sizeof pre, "%.2f", d.preprocess_seconds);
    std::printf("%-13s %-12s %8g %12lld %11s %10.2f %12s %9s %10.4g %9.3g\n", d.spec->name, dims.c_str(),
                static_cast<double>(d.spec->iso), static_cast<long long>(d.full_triangles), pre, d.convert_seconds,
                si(static_cast<double>(d.voxels()) / d.convert_seconds).c_str(), mb(d.store_bytes).c_str(),
                d.coarse_eps, d.delta);
  }
}

void print_rows(const std::vector<Row>& rows) {
  std::printf("\nExtraction (median wall time; 'vs baseline': the baseline's time on as many threads over this row's;\n"
              "store: a fresh brick cache per run, store-warm: one cache kept across runs; peak RSS of the process\n"
              "while the row ran, the volume and hierarchy it holds included; bytes read: compressed, per run)\n");
  std::printf("%-13s %-10s %-15s %9s %3s %11s %7s %10s %9s %8s %8s %10s\n", "dataset", "input", "mode", "eps", "thr",
              "triangles", "% full", "ms", "tri/s", "vs base", "peak MB", "read MB");
  std::string last;
  for (const Row& r : rows) {
    if (r.dataset != last && !last.empty()) std::printf("\n");
    last = r.dataset;
    std::printf("%-13s %-10s %-15s %9.4g %3d %11lld %7.2f %10s %9s %7.2fx %8s %10s\n", r.dataset.c_str(),
                r.input.c_str(), mode_label(r).c_str(), r.eps, r.threads, static_cast<long long>(r.triangles),
                100 * r.share, ms(r.seconds).c_str(), si(static_cast<double>(r.triangles) / r.seconds).c_str(),
                r.speedup, mb(r.peak_rss).c_str(), r.bytes_read ? mb(r.bytes_read).c_str() : "-");
  }
}

// The targets against the baseline, row by row.
struct TargetCheck {
  int eps0_rows = 0, eps0_met = 0, coarse_rows = 0, coarse_met = 0;
  int eps0_exact = 0;  // eps-0 rows with the baseline's triangle count, as they must have
  std::vector<std::string> missed;
};

std::string ratio(double r) {
  char b[32];
  std::snprintf(b, sizeof b, "%.2fx", r);
  return b;
}

TargetCheck check_targets(const std::vector<Row>& rows) {
  TargetCheck t;
  for (const Row& r : rows) {
    if (r.mode == "baseline") continue;
    char what[160];
    std::snprintf(what, sizeof what, "%s %s %s eps %g, %d thread%s: ", r.dataset.c_str(), r.input.c_str(),
                  mode_label(r).c_str(), r.eps, r.threads, r.threads == 1 ? "" : "s");
    if (r.eps == 0) {
      ++t.eps0_rows;
      if (r.share == 1.0) ++t.eps0_exact;
      if (r.speedup >= 1) ++t.eps0_met;
      else t.missed.push_back(what + ratio(r.speedup) + " (target 1x)");
    } else if (r.share <= kCoarseShare) {
      ++t.coarse_rows;
      if (r.speedup >= 10) ++t.coarse_met;
      else t.missed.push_back(what + ratio(r.speedup) + " (target 10x)");
    }
  }
  return t;
}

void print_targets(const TargetCheck& t) {
  std::printf("\nTargets against the baseline (same run, same thread count)\n");
  std::printf("  %-54s %d of %d rows%s\n", "eps = 0 gives the baseline's triangle count:", t.eps0_exact, t.eps0_rows,
              t.eps0_exact == t.eps0_rows ? "" : "  <- a bug: please report it");
  std::printf("  %-54s met in %d of %d rows\n", "eps = 0 at least as fast as the baseline:", t.eps0_met, t.eps0_rows);
  char coarse[80];
  std::snprintf(coarse, sizeof coarse, "at most %.0f%% of the triangles, at least 10x faster:", kCoarseShare * 100);
  std::printf("  %-54s met in %d of %d rows\n", coarse, t.coarse_met, t.coarse_rows);
  if (!t.missed.empty()) std::printf("  missed:\n");
  for (const std::string& m : t.missed) std::printf("    %s\n", m.c_str());
}

const Row* find_row(const std::vector<Row>& rows, const std::string& dataset, const std::string& mode, bool coarse,
                    int threads) {
  const Row* best = nullptr;  // in memory when there is such a row, else the cold store
  for (const Row& r : rows)
    if (r.dataset == dataset && r.mode == mode && (r.eps > 0) == coarse && r.threads == threads &&
        r.input != "store-warm" && (!best || r.input == "memory"))
      best = &r;
  return best;
}

nlohmann::ordered_json flying_edges(const std::vector<Row>& rows, int threads, bool print) {
  if (print) {
    std::printf("\nAgainst VTK 9.1 Flying Edges (one thread, full resolution, wall time without loading, measured on\n"
                "the development machine; issue 6). Targets: eps 0 within 2x of it (faster on the sphere), a coarse\n"
                "eps with at most %.0f%% of the triangles at least 10x faster.\n", kCoarseShare * 100);
    const std::string n = std::to_string(threads) + "t";
    std::printf("%-24s %8s %13s %13s %13s %13s %14s %14s %13s\n", "volume", "VTK ms", "baseline 1t", "eps 0, 1t",
                ("eps 0, " + n).c_str(), ("target 1t/" + n).c_str(), "coarse, 1t", ("coarse, " + n).c_str(),
                ("target 1t/" + n).c_str());
  }
  nlohmann::ordered_json out = nlohmann::ordered_json::array();
  for (const Reference& ref : kFlyingEdges) {
    const Row* base = find_row(rows, ref.dataset, "baseline", false, 1);
    nlohmann::ordered_json j = {{"volume", ref.what}, {"vtk_ms", ref.ms}};
    if (ref.triangles) j["vtk_triangles"] = ref.triangles;
    if (!base) {
      j["ours"] = nullptr;
      if (print) {
        const auto spec = std::find_if(suite().begin(), suite().end(),
                                       [&](const DatasetSpec& s) { return std::string(s.name) == ref.dataset; });
        std::printf("%-24s %8.0f   not run: %s\n", ref.what, ref.ms,
                    spec == suite().end() ? "no such volume in the shared data"
                    : spec->quick         ? "not selected by --dataset"
                                          : "in the full suite only (without --quick)");
      }
      out.push_back(j);
      continue;
    }
    const Row* e1 = find_row(rows, ref.dataset, "preserve", false, 1);
    const Row* en = find_row(rows, ref.dataset, "preserve", false, threads);
    const Row* c1 = find_row(rows, ref.dataset, "preserve", true, 1);
    const Row* cn = find_row(rows, ref.dataset, "preserve", true, threads);
    const double eps0_limit = std::string(ref.dataset) == "sphere512" ? ref.ms : 2 * ref.ms;
    // Flying Edges ran on one thread: the verdict on one thread first, then on all of ours.
    auto within = [](const Row* r, double limit_ms) { return r && r->seconds * 1e3 <= limit_ms; };
    const bool eps0_met_1 = within(e1, eps0_limit), eps0_met_n = within(en, eps0_limit);
    const bool coarse_met_1 = within(c1, ref.ms / 10), coarse_met_n = within(cn, ref.ms / 10);
    auto verdict = [](bool one, bool all) { return std::string(one ? "met" : "missed") + "/" + (all ? "met" : "missed"); };
    auto cell = [](const Row* r) { return r ? ms(r->seconds) + " (" + si(static_cast<double>(r->triangles)) + ")" : std::string("-"); };
    auto row_ms = [](const Row* r) { return r ? nlohmann::ordered_json(r->seconds * 1e3) : nlohmann::ordered_json(); };
    if (print)
      std::printf("%-24s %8.0f %13s %13s %13s %13s %14s %14s %13s\n", ref.what, ref.ms, ms(base->seconds).c_str(),
                  cell(e1).c_str(), cell(en).c_str(), verdict(eps0_met_1, eps0_met_n).c_str(), cell(c1).c_str(),
                  cell(cn).c_str(), verdict(coarse_met_1, coarse_met_n).c_str());
    j["ours"] = {{"baseline_1_thread_ms", base->seconds * 1e3}, {"triangles", base->triangles},
                 {"eps0_1_thread_ms", row_ms(e1)}, {"eps0_all_threads_ms", row_ms(en)}, {"eps0_target_ms", eps0_limit},
                 {"eps0_met_1_thread", eps0_met_1}, {"eps0_met_all_threads", eps0_met_n},
                 {"coarse_1_thread_ms", row_ms(c1)}, {"coarse_all_threads_ms", row_ms(cn)},
                 {"coarse_triangles", c1 ? c1->triangles : 0}, {"coarse_target_ms", ref.ms / 10},
                 {"coarse_met_1_thread", coarse_met_1}, {"coarse_met_all_threads", coarse_met_n}};
    out.push_back(j);
  }
  if (print) std::printf("(ms (triangles); our meshes are marching tetrahedra: about twice Flying Edges' triangles)\n");
  return out;
}

void print_table1(const nlohmann::ordered_json& t) {
  if (t.empty()) return;
  std::printf("\nPaper's Table 1 (algebraic function 65^3, iso 0, error indicator: bound; one thread)\n");
  std::printf("%-6s | %-16s | %-30s | %-30s\n", "eps", "paper: w/o  with", "ours without: triangles  ms", "ours with: triangles  ms");
  for (const auto& r : t) {
    std::printf("%-6s | %7d %8d | %20lld %8s | %20lld %8s\n", r["eps"].get<std::string>().c_str(),
                r["paper"]["without"].get<int>(), r["paper"]["with"].get<int>(),
                r["without"]["triangles"].get<long long>(), ms(r["without"]["seconds"].get<double>()).c_str(),
                r["with"]["triangles"].get<long long>(), ms(r["with"]["seconds"].get<double>()).c_str());
  }
  std::printf("The paper's eps scale is not stated (docs/METHOD.md): compare the shape of the columns. Its speed claim\n"
              "(Sec. 4.6): %s triangles/s extracted and drawn on one processor, %s on a multiprocessor (2000).\n",
              si(kPaperTrianglesPerSecondOne).c_str(), si(kPaperTrianglesPerSecondMany).c_str());
}

// ---- JSON ------------------------------------------------------------------------------------

std::string cpu_model() {
  std::ifstream in("/proc/cpuinfo");
  for (std::string line; std::getline(in, line);)
    if (line.rfind("model name", 0) == 0) return line.substr(line.find(':') + 2);
  return "unknown";
}

nlohmann::ordered_json rows_json(const std::vector<Row>& rows) {
  nlohmann::ordered_json out = nlohmann::ordered_json::array();
  for (const Row& r : rows) {
    nlohmann::ordered_json j = {{"dataset", r.dataset}, {"input", r.input}, {"mode", r.mode}, {"eps", r.eps}};
    if (r.mode == "simplify") j["delta"] = r.delta;
    j.update({{"threads", r.threads}, {"triangles", r.triangles}, {"share_of_full", r.share},
              {"seconds", r.seconds}, {"runs", r.runs},
              {"triangles_per_second", static_cast<double>(r.triangles) / r.seconds},
              {"speedup_vs_baseline", r.speedup}, {"peak_rss_bytes", r.peak_rss}, {"bytes_read", r.bytes_read}});
    out.push_back(j);
  }
  return out;
}

nlohmann::ordered_json datasets_json(const std::vector<DatasetResult>& ds) {
  nlohmann::ordered_json out = nlohmann::ordered_json::array();
  for (const DatasetResult& d : ds) {
    nlohmann::ordered_json j = {{"name", d.spec->name}, {"description", d.spec->description},
                                {"dims", d.dims}, {"iso", d.spec->iso}, {"value_range", {d.value_min, d.value_max}},
                                {"full_triangles", d.full_triangles}, {"coarse_eps", d.coarse_eps}, {"delta", d.delta}};
    j["preprocess_seconds"] = d.preprocess_seconds >= 0 ? nlohmann::ordered_json(d.preprocess_seconds) : nullptr;
    j["convert_seconds"] = d.convert_seconds;
    j["convert_voxels_per_second"] = static_cast<double>(d.voxels()) / d.convert_seconds;
    j["store_bytes"] = d.store_bytes;
    out.push_back(j);
  }
  return out;
}

// ---- The command -----------------------------------------------------------------------------

std::vector<const DatasetSpec*> selected(const BenchArgs& a) {
  std::vector<const DatasetSpec*> out;
  for (const std::string& name : a.datasets) {
    const auto it = std::find_if(suite().begin(), suite().end(), [&](const DatasetSpec& s) { return name == s.name; });
    if (it == suite().end()) {
      std::string names;
      for (const DatasetSpec& s : suite()) names += std::string(names.empty() ? "" : ", ") + s.name;
      throw CLI::ValidationError("--dataset", "unknown dataset '" + name + "' (one of " + names + ")");
    }
  }
  for (const DatasetSpec& s : suite()) {
    const bool named = std::find(a.datasets.begin(), a.datasets.end(), s.name) != a.datasets.end();
    if (a.datasets.empty() ? (s.quick || !a.quick) : named) out.push_back(&s);
  }
  return out;
}

int run_bench(const BenchArgs& a) {
  const std::vector<const DatasetSpec*> specs = selected(a);
  if (!a.json.empty()) AtomicFile check(a.json);  // a bad --json directory fails now, not after the suite
  const bool progress = progress_enabled(a.quiet);
  // The stores' folder, removed with them when the command ends, however it ends.
  const TempDir work(std::filesystem::path(a.work_dir.empty() ? std::filesystem::temp_directory_path().string()
                                                               : a.work_dir) /
                     ("isotope-bench-" + std::to_string(::getpid())));
  keep_freed_brick_memory();  // as isotope extract does for a store
  const InterruptGuard guard;  // Ctrl-C stops between runs, and the work directory is removed
  Suite suite(a, work.path(), progress);
  const auto start = std::chrono::steady_clock::now();
  std::vector<std::string> skipped;
  for (const DatasetSpec* spec : specs) {
    Volume volume;
    if (spec->file) {
      const std::filesystem::path file = std::filesystem::path(a.data) / spec->file;
      std::error_code ec;
      if (!std::filesystem::is_regular_file(file, ec)) {
        skipped.push_back(std::string(spec->name) + " (" + file.string() + " not found; pass --data DIR)");
        continue;
      }
      volume = read_volume(VolumeSource{file.string(), std::nullopt, std::nullopt});
    } else {
      if (progress) std::fprintf(stderr, "\r\033[Kisotope: bench %s: generating", spec->name);
      const ThreadCap cap(suite.threads());
      volume = spec->generate();
    }
    if (InterruptGuard::interrupted()) throw IoError("interrupted");
    suite.run(*spec, volume);
  }
  if (progress) std::fprintf(stderr, "\r\033[K");
  const double total = seconds_since(start);

  std::printf("isotope bench%s: %s, %u hardware threads, %d used; %.1f s\n", a.quick ? " --quick" : "",
              cpu_model().c_str(), std::thread::hardware_concurrency(), suite.threads(), total);
  print_preprocessing(suite.datasets());
  print_rows(suite.rows());
  const TargetCheck targets = check_targets(suite.rows());
  print_targets(targets);
  const nlohmann::ordered_json fe = flying_edges(suite.rows(), suite.threads(), true);
  print_table1(suite.table1());
  for (const std::string& s : skipped) std::printf("skipped: %s\n", s.c_str());

  if (!a.json.empty()) {
    nlohmann::ordered_json j;
    j["isotope_version"] = ISOTOPE_VERSION;
    j["suite"] = a.quick ? "quick" : "full";
    j["machine"] = {{"cpu", cpu_model()}, {"hardware_threads", std::thread::hardware_concurrency()},
                    {"threads", suite.threads()}};
    j["policy"] = {{"min_runs", suite.policy().min_runs}, {"max_runs", suite.policy().max_runs},
                   {"min_seconds", suite.policy().min_seconds}, {"statistic", "median"},
                   {"cache_mb", a.cache_mb}};
    j["seconds"] = total;
    j["datasets"] = datasets_json(suite.datasets());
    j["rows"] = rows_json(suite.rows());
    j["targets"] = {{"eps0_rows", targets.eps0_rows}, {"eps0_exact", targets.eps0_exact}, {"eps0_met", targets.eps0_met},
                    {"coarse_rows", targets.coarse_rows}, {"coarse_met", targets.coarse_met},
                    {"missed", targets.missed}};
    j["flying_edges"] = fe;
    j["paper_table1"] = suite.table1();
    j["paper_triangles_per_second"] = {{"one_processor", kPaperTrianglesPerSecondOne},
                                       {"multiprocessor", kPaperTrianglesPerSecondMany}};
    j["skipped"] = skipped;
    write_json_file(j, a.json);
  }
  return 0;
}

}  // namespace

Command add_bench_command(CLI::App& app) {
  auto a = std::make_shared<BenchArgs>();
  CLI::App* cmd = app.add_subcommand(
      "bench",
      "Time extraction on a fixed suite against full-resolution marching tetrahedra, in the same run;\n"
      "print the paper's Table 1 and VTK Flying Edges reference times beside ours");
  cmd->add_flag("--quick", a->quick, "The small suite (algebraic 65^3 and 257^3, the shared volumes): under a minute");
  cmd->add_option("--json", a->json, "Also write every number as JSON")->type_name("F.json");
  cmd->add_option("--threads", a->threads, "Threads for the parallel rows (0 = all cores)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->add_option("--dataset", a->datasets, "Run only this dataset (repeatable): algebraic65, algebraic257, bolt,\n"
                                            "hydrogen, ironProt, neghip, noise384, noise513, sphere512")
      ->type_name("NAME");
  cmd->add_option("--data", a->data, "Directory of the shared volumes (skipped if missing)")
      ->type_name("DIR")
      ->capture_default_str();
  cmd->add_option("--work-dir", a->work_dir, "Where the temporary stores go (default: the system's temp directory)")
      ->type_name("DIR");
  cmd->add_option("--cache-mb", a->cache_mb, "Brick cache of the store rows, in MB")
      ->check(CLI::Range(int64_t{1}, int64_t{1} << 30))
      ->capture_default_str();
  cmd->add_flag("-q,--quiet", a->quiet, "No progress lines on stderr");
  return [a] { return run_bench(*a); };
}

}  // namespace isotope::tools
