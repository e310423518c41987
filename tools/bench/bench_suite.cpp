// isotope bench: times the product on a fixed suite of volumes as a user meets it, beside the
// obvious alternative measured in the same run: full-resolution marching tetrahedra over the raw
// array (on one thread and on all of them). Extraction from the hierarchy in memory, from a store
// with a warm brick cache (an interactive session) and from a cold one (a new process, the store
// dropped from the OS page cache: what `isotope extract STORE` meets the first time); one-shot
// extraction from the raw file, the whole process with its mesh written; convert against its
// ceiling (zstd over the values as float32 on all threads). Beside them: scikit-image's
// marching_cubes on the same file and VTK's Flying Edges on the same array (python3-skimage and
// python3-vtk9, run here) and the paper's Table 1. Then the speed targets (README, "Performance"), row by
// row, met or missed. `--scale` runs the large-volume row instead.
#include "tools/bench/bench_suite.h"

#include <fcntl.h>
#include <malloc.h>
#include <oneapi/tbb/global_control.h>
#include <unistd.h>
#include <zstd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "engine/core/parallel.h"
#include "engine/extract/extract_drivers.h"
#include "engine/hierarchy/hierarchy.h"
#include "engine/synthetic/fields.h"
#include "io/file/atomic_file.h"
#include "io/file/temp_dir.h"
#include "io/volume/raw_reader.h"
#include "io/volume/volume_reader.h"
#include "io/volume/volume_writer.h"
#include "isotope/error.h"
#include "isotope/source.h"
#include "isotope/version.h"
#include "tools/support/child_run.h"
#include "tools/support/command_line.h"
#include "tools/support/interrupt_guard.h"
#include "tools/support/paper_table1.h"
#include "tools/support/peak_memory.h"
#include "tools/support/report.h"

namespace isotope::bench {
using namespace isotope::tools;
namespace {

namespace fs = std::filesystem;
using json = nlohmann::ordered_json;

// ---- The suite -------------------------------------------------------------------------------

struct DatasetSpec {
  const char* name;
  const char* description;
  const char* file;  // in --data; nullptr: generated (and written as a float32 raw file for the process rows)
  float iso;
  bool quick;      // part of --quick
  bool in_memory;  // also the hierarchy in memory (a one-shot extraction's path)
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
      {"embryo", "embryo 256^3 uint8 (noisy CT)", "embryo_256x256x256_uint8.raw", 64.5f, true, true, nullptr},
      {"noise384", "smooth random field (24 Gaussian bumps), 384^3", nullptr, 0.0f, false, false,
       [] { return generate_noise(384, 384); }},
      {"noise513", "smooth random field (24 Gaussian bumps), 513^3", nullptr, 0.0f, false, true,
       [] { return generate_noise(513, 513); }},
      {"sphere512", "sphere of radius 0.6 in [-1,1]^3, 512^3", nullptr, 0.0f, false, false,
       [] { return generate_sphere(512); }},
  };
  return s;
}

// Store sizes of format version 2 (README, measured the day it landed; embryo and algebraic 257^3
// by this bench's predecessor), over the raw input: the store must be no larger.
const std::map<std::string, double> kFormat2Ratio = {{"bolt", 0.268},     {"neghip", 0.804}, {"ironProt", 0.819},
                                                     {"hydrogen", 0.956}, {"embryo", 0.547}, {"algebraic257", 1.285}};

// The paper's speed claim (Sec. 4.6, quoting its ref. [6]): extraction and drawing together.
constexpr double kPaperTrianglesPerSecondOne = 300000, kPaperTrianglesPerSecondMany = 800000;

constexpr size_t kLeastPairs = 7;       // the fewest pairs of runs a warm-against-memory ratio takes
constexpr double kCoarseShare = 0.10;   // the coarse eps keeps at most this share of the triangles
constexpr double kDeltaOfRange = 0.02;  // simplify's delta, as a share of the value range

// ---- Measuring -------------------------------------------------------------------------------

struct Policy {
  size_t min_runs = 3, max_runs = 50;
  double min_seconds = 1.0;  // keep repeating a fast case until it has run this long
};

struct Row {
  std::string dataset, input, mode;  // input: raw, memory, store-warm, store-cold, one-shot, convert+extract
  double eps = 0, delta = 0;
  int threads = 1;
  int64_t triangles = 0;
  double seconds = 0;          // median of `runs`: the extraction (the process's own report for children)
  double process_seconds = 0;  // children: median of the whole process, mesh written
  int runs = 0;
  uint64_t peak_rss = 0, bytes_read = 0;
  uint64_t bytes_written = 0;  // quiet children: the mesh file's size
  double speedup = 0;          // baseline's median at the same thread count over ours
  double share = 0;            // triangles over the full-resolution mesh's
  // store-cold: the same process with the store in the page cache (its extraction's median), and
  // the row's floor: that plus the bytes it reads at the disk's sequential rate.
  double warm_seconds = 0, floor_seconds = 0;
  std::string note;
};

// The volumes the speed targets name; the small ones run in milliseconds, where a process's start-up
// is most of what is measured.
bool names_a_target(const std::string& dataset) {
  return dataset == "algebraic257" || dataset == "embryo" || dataset == "noise513";
}

// The row of DATASET, INPUT and MODE on THREADS, at a coarse eps or at 0; null where none ran.
const Row* find_row(const std::vector<Row>& rows, const std::string& dataset, const std::string& input,
                    const std::string& mode, bool coarse, int threads) {
  for (const Row& r : rows)
    if (r.dataset == dataset && r.input == input && r.mode == mode && (r.eps > 0) == coarse && r.threads == threads)
      return &r;
  return nullptr;
}

class ThreadCap {
 public:
  explicit ThreadCap(int threads)
      : control_(tbb::global_control::max_allowed_parallelism, static_cast<size_t>(threads)) {}

 private:
  tbb::global_control control_;
};

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0 : v[v.size() / 2];
}

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
  row.seconds = median(times);
  row.runs = static_cast<int>(times.size());
  row.peak_rss = peak_rss_bytes();
}

// One child run of EXECUTABLE (an isotope); throws with its output when it fails.
ChildRun child_of(const std::string& executable, const std::vector<std::string>& args, const fs::path& work) {
  std::vector<std::string> argv = {executable};
  argv.insert(argv.end(), args.begin(), args.end());
  const ChildRun r = run_child(argv, (work / "child.log").string());
  if (InterruptGuard::interrupted()) throw IoError("interrupted");
  if (r.code != 0) throw IoError(executable + " " + args.front() + " failed in the benchmark: " + r.output);
  return r;
}
// One child run of this executable.
ChildRun child(const std::vector<std::string>& args, const fs::path& work) {
  return child_of(self_executable(), args, work);
}

// What `EXECUTABLE --version` prints ("isotope 0.1.0"), or an OptionError for --reference where it
// is not an isotope executable that runs.
std::string reference_version(const std::string& executable, const fs::path& work) {
  const ChildRun r = run_child({executable, "--version"}, (work / "child.log").string());
  std::string version = r.output.substr(0, r.output.find('\n'));
  if (r.code != 0 || version.rfind("isotope ", 0) != 0)
    throw OptionError("reference", "'" + executable + "' is not an isotope executable (its --version " +
                                       (r.code == -1 ? std::string("did not run") : "printed '" + version + "'") + ")");
  return version;
}

// What `isotope extract` prints on stdout when it ends (summary_line): the
// triangles and its preprocessing and extraction seconds (to four significant digits: the cold
// rows of the small volumes take a few milliseconds). The timed runs read these instead of
// asking for a report, whose per-component measures (--report) would be timed with the process.
struct Summary {
  int64_t triangles = 0;
  double preprocess_seconds = 0, extract_seconds = 0;
};
Summary parse_summary(const std::string& output) {
  Summary s;
  const size_t at = output.find(" triangles, ");
  const size_t start = output.rfind(": ", at);
  const size_t pre = output.find("; preprocess ", at);
  long long triangles = 0;
  if (at == std::string::npos || start == std::string::npos || pre == std::string::npos ||
      std::sscanf(output.c_str() + start + 2, "%lld", &triangles) != 1 ||
      std::sscanf(output.c_str() + pre, "; preprocess %lf s, extract %lf s", &s.preprocess_seconds,
                  &s.extract_seconds) != 2)
    throw IoError("isotope extract printed no summary line the benchmark can read: " + output);
  s.triangles = triangles;
  return s;
}

// ---- One dataset -----------------------------------------------------------------------------

struct DatasetResult {
  const DatasetSpec* spec = nullptr;
  std::array<int64_t, 3> dims{};
  double value_min = 0, value_max = 0;
  int64_t full_triangles = 0;
  double coarse_eps = 0, delta = 0;
  double preprocess_seconds = -1;  // the hierarchy in memory, all fields; -1: not done
  double convert_seconds = 0, convert_peak_mb = 0, ceiling_seconds = 0;
  uint64_t store_bytes = 0, raw_bytes = 0;
  json preview;  // embryo: a triangle budget in simplify mode (delta chosen)
  // A warm store's time over memory's, per case, from runs taken in alternation (paired_ratios).
  struct Paired {
    std::string mode;
    bool coarse = false;
    int threads = 1;
    double ratio = 0;  // the median of the pairs' ratios
    int pairs = 0;
  };
  std::vector<Paired> warm_over_memory;
  // A case run as whole processes of two executables in alternation, with the same arguments but
  // one: each one's median wall time and greatest peak memory over the rounds.
  struct Versus {
    std::string what;  // convert, one-shot preserve, one-shot none
    int threads = 1;   // ours
    double ours = 0, theirs = 0;
    int64_t ours_rss_kb = 0, theirs_rss_kb = 0;
    int rounds = 0;
  };
  std::vector<Versus> against_reference;  // theirs: --reference's, on as many threads
  Versus convert_threads;                 // theirs: ours on one thread; rounds 0 where not run
  const Paired* paired(const std::string& mode, bool coarse, int threads) const {
    for (const Paired& p : warm_over_memory)
      if (p.mode == mode && p.coarse == coarse && p.threads == threads) return &p;
    return nullptr;
  }
  int64_t voxels() const { return dims[0] * dims[1] * dims[2]; }
};

// The disk rates are measured in blocks of this size.
constexpr size_t kScratchBlock = size_t{1} << 20;

// BYTES of a pattern, for the disk rates' files.
std::vector<uint8_t> scratch_bytes(size_t bytes) {
  std::vector<uint8_t> block(bytes);
  for (size_t i = 0; i < block.size(); ++i) block[i] = static_cast<uint8_t>(i * 2654435761u >> 24);
  return block;
}

// BLOCKS blocks of bytes that do not repeat within a block, written to FILE as isotope writes its
// outputs: into a temporary file, flushed to the disk, renamed into place. Returns the bytes.
uint64_t write_scratch(const fs::path& file, size_t blocks) {
  const std::vector<uint8_t> block = scratch_bytes(kScratchBlock);
  AtomicFile out(file.string());
  for (size_t i = 0; i < blocks; ++i) out.write(block.data(), block.size());
  out.commit();
  return uint64_t{blocks} * kScratchBlock;
}

// The disk's sequential read rate in bytes/s, for the cold rows' floors: a file of 256 MB written
// to `dir`, dropped from the page cache, read back in reads of 1 MB.
double sequential_read_rate(const fs::path& dir) {
  const fs::path file = dir / "disk-rate.bin";
  const uint64_t written = write_scratch(file, 256);
  if (!evict_from_page_cache(file.string())) throw IoError(file.string() + ": cannot drop it from the page cache");
  const int fd = ::open(file.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) throw IoError(file.string() + ": cannot open it again");
  std::vector<uint8_t> block(kScratchBlock);
  const auto start = std::chrono::steady_clock::now();
  uint64_t total = 0;
  for (ssize_t n; (n = ::pread(fd, block.data(), block.size(), static_cast<off_t>(total))) > 0;)
    total += static_cast<uint64_t>(n);
  const double seconds = seconds_since(start);
  ::close(fd);
  fs::remove(file);
  if (total != written) throw IoError(file.string() + ": read back short");
  return static_cast<double>(total) / seconds;
}

// The rate in bytes/s at which a mesh's bytes reach the disk as `isotope extract` writes them (a
// region in pieces of AtomicFile::kRegionPieceBytes, flushed, renamed), for the one-shot verdict's
// estimate of a write after the march: 64 MB, about the size of embryo's eps 0 PLY, timed whole.
double durable_write_rate(const fs::path& dir) {
  const fs::path file = dir / "disk-write-rate.bin";
  const uint64_t bytes = uint64_t{64} << 20;
  const std::vector<uint8_t> piece = scratch_bytes(AtomicFile::kRegionPieceBytes);
  const auto start = std::chrono::steady_clock::now();
  {
    AtomicFile out(file.string());
    const uint64_t at = out.append_region(bytes);
    for (uint64_t done = 0; done < bytes; done += piece.size()) out.write_region(at + done, piece.data(), piece.size());
    out.commit();
  }
  const double seconds = seconds_since(start);
  fs::remove(file);
  return static_cast<double>(bytes) / seconds;
}

class Suite {
 public:
  Suite(const SuiteOptions& a, fs::path work, bool progress) : a_(a), work_(std::move(work)), progress_(progress) {
    threads_ = a.threads > 0 ? a.threads : static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
    if (a.quick) policy_ = {3, 20, 0.2};
    // A small volume's cold row takes a few milliseconds, and one read that waits longer moves it
    // by a third: such rows run until they add up to the time bound (at most 15 or 25 runs), where
    // a row of a large volume stops after three.
    cold_policy_ = a.quick ? Policy{3, 15, 0.3} : Policy{3, 25, 1.0};
  }

  int threads() const { return threads_; }
  const Policy& policy() const { return policy_; }
  double disk_rate() const { return disk_rate_; }    // bytes/s; 0 until a cold row measured it
  double write_rate() const { return write_rate_; }  // bytes/s; 0 until a quiet one-shot row measured it
  std::vector<Row>& rows() { return rows_; }
  std::vector<DatasetResult>& datasets() { return datasets_; }
  json& table1() { return table1_; }
  json& peers() { return peers_; }
  std::vector<std::string>& skipped() { return skipped_; }

  void run(const DatasetSpec& spec, const Volume& volume, const std::string& raw_file) {
    DatasetResult d;
    d.spec = &spec;
    d.dims = volume.dims;
    const auto [lo, hi] = std::minmax_element(volume.values.begin(), volume.values.end());
    d.value_min = *lo;
    d.value_max = *hi;
    d.delta = kDeltaOfRange * (d.value_max - d.value_min);
    d.raw_bytes = fs::file_size(raw_file);
    const size_t first = rows_.size();
    baseline_seconds_.clear();
    baseline(spec, volume, d);
    const std::string store = (work_ / (std::string(spec.name) + ".isotope")).string();
    convert(spec, volume, raw_file, store, d);
    {
      d.store_bytes = fs::file_size(store);
      d.coarse_eps = coarse_eps(store, spec, d);
      if (spec.in_memory) {
        say(spec, "building the hierarchy in memory");
        std::optional<Hierarchy> memory;
        {
          const ThreadCap cap(threads_);
          const auto start = std::chrono::steady_clock::now();
          memory.emplace(Hierarchy::build(volume));
          d.preprocess_seconds = seconds_since(start);
        }
        memory_rows(spec, d, *memory);
        paired_ratios(spec, d, *memory, store);
        if (spec.name == std::string("algebraic65")) paper_table1(*memory);
      }
      warm_rows(spec, d, store);
    }
    cold_rows(spec, d, store);
    process_rows(spec, d, raw_file);
    versus_rows(spec, d, raw_file);
    if (spec.name == std::string("embryo")) d.preview = preview(spec, d, store);
    peer_rows(spec, d, raw_file);
    fs::remove(store);
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
  std::vector<int> thread_counts() const { return threads_ > 1 ? std::vector<int>{1, threads_} : std::vector<int>{1}; }
  void finish(Row& r) {
    r.speedup = baseline_seconds_.at(r.threads) / r.seconds;
    rows_.push_back(r);
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

  // convert as a user runs it (a process, all threads, the default budget), with its peak memory;
  // and its ceiling: zstd at the store's level on all threads over the values as float32, in
  // memory (what `zstd -3 -T0` does to a float32 copy of the volume).
  void convert(const DatasetSpec& spec, const Volume& volume, const std::string& raw, const std::string& store,
               DatasetResult& d) {
    say(spec, "converting to a store");
    const ChildRun r = child({"convert", raw, store, "--threads", std::to_string(threads_), "-q"}, work_);
    d.convert_seconds = r.seconds;
    d.convert_peak_mb = static_cast<double>(r.max_rss_kb) / 1024;
    say(spec, "the convert ceiling");
    std::vector<double> times;
    for (int i = 0; i < 3; ++i) {
      const auto start = std::chrono::steady_clock::now();
      compress_all_threads(volume.values);
      times.push_back(seconds_since(start));
    }
    d.ceiling_seconds = *std::min_element(times.begin(), times.end());
  }

  size_t compress_all_threads(const std::vector<float>& values) const {
    const std::unique_ptr<ZSTD_CCtx, size_t (*)(ZSTD_CCtx*)> cctx(ZSTD_createCCtx(), ZSTD_freeCCtx);
    ZSTD_CCtx_setParameter(cctx.get(), ZSTD_c_compressionLevel, 3);
    ZSTD_CCtx_setParameter(cctx.get(), ZSTD_c_nbWorkers, threads_ > 1 ? threads_ : 0);
    std::vector<char> out(ZSTD_compressBound(values.size() * sizeof(float)));
    const size_t n = ZSTD_compress2(cctx.get(), out.data(), out.size(), values.data(), values.size() * sizeof(float));
    if (ZSTD_isError(n)) throw IoError(std::string("zstd: ") + ZSTD_getErrorName(n));
    return n;
  }

  // The eps a triangle budget of 10% of the full triangles chooses without topology control (the
  // finest whose mesh fits; on volumes over 257 a side, one whose mesh holds 90-100% of it, chosen
  // from a sample: docs/METHOD.md), untimed; every coarse row uses it, whatever its mode. A plain
  // eps: where the search stepped into the tie classes of a key, the eps just above that key.
  double coarse_eps(const std::string& store, const DatasetSpec& spec, const DatasetResult& d) const {
    say(spec, "choosing the coarse eps");
    const Source volume = open_store(store);
    ExtractOptions o;
    o.iso = spec.iso;
    o.topology = TopologyMode::none;
    o.max_triangles = std::max<int64_t>(1, static_cast<int64_t>(kCoarseShare * static_cast<double>(d.full_triangles)));
    ExtractStats stats;
    volume.extract(o, {}, &stats);
    return stats.chosen_eps_ties >= 0 ? std::nextafter(stats.chosen_eps, std::numeric_limits<double>::infinity())
                                      : stats.chosen_eps;
  }

  // A store as isotope extract and isotope serve open it (isotope::Source), through --cache-mb.
  Source open_store(const std::string& store) const {
    OpenOptions options;
    options.cache_mb = a_.cache_mb;
    options.tune_allocator = true;
    return open_volume(VolumeSpec{store, std::nullopt, std::nullopt}, options);
  }

  ExtractOptions options(const DatasetSpec& spec, TopologyMode mode, double eps, double delta) const {
    ExtractOptions o;
    o.iso = spec.iso;
    o.eps = eps;
    o.topology = mode;
    o.delta = mode == TopologyMode::simplify ? delta : 0.0;
    return o;
  }

  struct Case {
    TopologyMode mode;
    bool coarse;
    int threads;
  };
  std::vector<Case> cases() const {
    const int n = threads_;
    std::vector<Case> c = {{TopologyMode::preserve, false, 1}};
    if (n > 1) c.push_back({TopologyMode::preserve, false, n});
    c.push_back({TopologyMode::none, true, n});
    c.push_back({TopologyMode::preserve, true, 1});
    if (n > 1) c.push_back({TopologyMode::preserve, true, n});
    c.push_back({TopologyMode::simplify, true, n});
    return c;
  }

  void memory_rows(const DatasetSpec& spec, const DatasetResult& d, const Hierarchy& memory) {
    for (const Case& c : cases()) {
      say(spec, ("memory, " + std::string(to_string(c.mode))).c_str());
      const ExtractOptions o = options(spec, c.mode, c.coarse ? d.coarse_eps : 0.0, d.delta);
      Row r = row(spec, "memory", std::string(to_string(c.mode)).c_str(), o.eps, c.threads);
      r.delta = o.delta;
      measure(policy_, r, [&](uint64_t&) { return static_cast<int64_t>(extract(memory, o).triangles.size()); });
      finish(r);
    }
  }

  // The warm store's time over memory's, case by case, from the two run in alternation, the order
  // swapped every pair, each pair's ratio taken and their median kept: rows measured minutes apart
  // on a shared machine drift by up to a third between runs of the same build (a few-millisecond
  // row most), which the two rows' medians alone would read as a verdict at 1.25x. The rows keep
  // their own medians and peak memory (measured apart, the hierarchy gone for the warm rows).
  void paired_ratios(const DatasetSpec& spec, DatasetResult& d, const Hierarchy& memory, const std::string& store) {
    const Source volume = open_store(store);
    for (const Case& c : cases()) {
      say(spec, ("warm store against memory, " + std::string(to_string(c.mode))).c_str());
      const ExtractOptions o = options(spec, c.mode, c.coarse ? d.coarse_eps : 0.0, d.delta);
      const ThreadCap cap(c.threads);
      volume.extract(o);  // fills the cache, as the warm rows' first run
      auto timed = [](const auto& f) {
        const auto start = std::chrono::steady_clock::now();
        f();
        return seconds_since(start);
      };
      // More pairs than a row's runs: a ratio near 1.25x is decided by them (at least 7 pairs
      // and a second; with 4, algebraic 257^3's coarse row on one thread read 1.34x where 31 in
      // one process read 1.19-1.20x).
      const size_t least = std::max<size_t>(policy_.min_runs, kLeastPairs);
      const double seconds = std::max(policy_.min_seconds, 1.0);
      std::vector<double> ratios;
      double total = 0;
      while (ratios.size() < least || (total < seconds && ratios.size() < policy_.max_runs)) {
        if (InterruptGuard::interrupted()) throw IoError("interrupted");
        double in_memory = 0, warm = 0;
        auto run_memory = [&] { in_memory = timed([&] { extract(memory, o); }); };
        auto run_warm = [&] { warm = timed([&] { volume.extract(o); }); };
        if (ratios.size() % 2 == 0)
          run_memory(), run_warm();
        else
          run_warm(), run_memory();
        ratios.push_back(warm / in_memory);
        total += in_memory + warm;
      }
      d.warm_over_memory.push_back(
          {std::string(to_string(c.mode)), c.coarse, c.threads, median(ratios), static_cast<int>(ratios.size())});
    }
  }

  // One cache kept across runs: an interactive session (isotope serve). The first run, which
  // fills it, is not timed.
  void warm_rows(const DatasetSpec& spec, const DatasetResult& d, const std::string& store) {
    const Source volume = open_store(store);
    for (const Case& c : cases()) {
      if (!spec.in_memory && c.threads == 1 && c.coarse) continue;
      say(spec, ("store, warm cache, " + std::string(to_string(c.mode))).c_str());
      const ExtractOptions o = options(spec, c.mode, c.coarse ? d.coarse_eps : 0.0, d.delta);
      volume.extract(o);
      Row r = row(spec, "store-warm", std::string(to_string(c.mode)).c_str(), o.eps, c.threads);
      r.delta = o.delta;
      measure(policy_, r, [&](uint64_t& bytes) {
        const uint64_t before = volume.info().bytes_read;
        const int64_t triangles = static_cast<int64_t>(volume.extract(o).triangles.size());
        bytes += volume.info().bytes_read - before;
        return triangles;
      });
      finish(r);
    }
  }

  // `isotope extract STORE` in a new process with the store dropped from the page cache first:
  // what a user meets the first time. The row's time is the extraction the process reports (read
  // from the disk as it goes), comparable with the baseline; process_seconds is the whole run.
  // Runs `isotope extract ARGS -o MESH` as new processes until the cold policy is met. The row
  // gets the median of the time each prints (its extraction, and its preprocessing when
  // `preprocess`) and of its whole run, its triangles and the peak RSS over the runs. BEFORE runs
  // ahead of each, untimed.
  // QUIET: with -q, as a user who wants the mesh only runs it: the process prints no summary (and
  // so measures no topology for it), and the row's time is the whole process's.
  void extract_processes(Row& r, std::vector<std::string> args, const fs::path& mesh, bool preprocess,
                         const std::function<void()>& before = {}, bool quiet = false) {
    args.insert(args.end(), {"-o", mesh.string()});
    if (quiet) args.push_back("-q");
    std::vector<double> times, process;
    double total = 0;
    uint64_t peak = 0;
    while (times.size() < cold_policy_.min_runs ||
           (total < cold_policy_.min_seconds && times.size() < cold_policy_.max_runs)) {
      if (before) before();
      fs::remove(mesh);  // replacing the last run's mesh would time freeing its pages too
      const ChildRun c = child(args, work_);
      if (quiet) {
        times.push_back(c.seconds);
        r.bytes_written = fs::file_size(mesh);
      } else {
        const Summary s = parse_summary(c.output);
        times.push_back(s.extract_seconds + (preprocess ? s.preprocess_seconds : 0));
        r.triangles = s.triangles;
      }
      process.push_back(c.seconds);
      total += c.seconds;
      peak = std::max(peak, static_cast<uint64_t>(c.max_rss_kb) << 10);
    }
    fs::remove(mesh);
    r.seconds = median(times);
    r.process_seconds = median(process);
    r.runs = static_cast<int>(times.size());
    r.peak_rss = peak;
  }

  Row cold_row(const DatasetSpec& spec, const std::string& store, const ExtractOptions& o, int threads) {
    Row r = row(spec, "store-cold", std::string(to_string(o.topology)).c_str(), o.eps, threads);
    r.delta = o.delta;
    std::vector<std::string> args = {"extract",
                                     store,
                                     "--iso=" + number(o.iso),
                                     "--eps=" + number(o.eps),
                                     "--topology=" + std::string(to_string(o.topology)),
                                     "--threads",
                                     std::to_string(threads)};
    if (o.topology == TopologyMode::simplify) args.push_back("--delta=" + number(o.delta));
    extract_processes(r, args, work_ / "cold.ply", false, [&] { evict_from_page_cache(store); });
    // Once more with a report, untimed: the bytes read (the same in every cold run).
    evict_from_page_cache(store);
    std::vector<std::string> reported = args;
    reported.insert(reported.end(),
                    {"-o", (work_ / "cold.ply").string(), "-q", "--report", (work_ / "cold.json").string()});
    child(reported, work_);
    std::ifstream in(work_ / "cold.json");
    r.bytes_read = nlohmann::json::parse(in).at("bytes_read").get<uint64_t>();
    fs::remove(work_ / "cold.ply");
    fs::remove(work_ / "cold.json");
    // The floor: the same runs with what they read left in the page cache by the run above, plus
    // reading those bytes at the disk's sequential rate.
    if (disk_rate_ == 0) disk_rate_ = sequential_read_rate(work_);
    Row warm = r;
    extract_processes(warm, args, work_ / "cold.ply", false);
    r.warm_seconds = warm.seconds;
    r.floor_seconds = warm.seconds + static_cast<double>(r.bytes_read) / disk_rate_;
    return r;
  }

  static std::string number(double v) {
    char b[48];
    std::snprintf(b, sizeof b, "%.17g", v);
    return b;
  }

  void cold_rows(const DatasetSpec& spec, const DatasetResult& d, const std::string& store) {
    for (const Case& c : cases()) {
      if (c.mode == TopologyMode::simplify) continue;
      say(spec, ("store, cold, " + std::string(to_string(c.mode))).c_str());
      Row r = cold_row(spec, store, options(spec, c.mode, c.coarse ? d.coarse_eps : 0.0, d.delta), c.threads);
      finish(r);
    }
    if (threads_ > 1) {  // mode none on one thread too: the coarse target's one-thread verdict
      Row r = cold_row(spec, store, options(spec, TopologyMode::none, d.coarse_eps, 0), 1);
      finish(r);
    }
  }

  // Whole processes from the raw file: eps 0 (no hierarchy at all) on one thread and on all, and
  // a coarse none extraction (the hierarchy it needs only) against convert + extract of the store.
  void process_rows(const DatasetSpec& spec, const DatasetResult& d, const std::string& raw) {
    const auto extract_args = [&](TopologyMode mode, double eps, int threads) {
      return std::vector<std::string>{"extract",
                                      raw,
                                      "--iso=" + number(spec.iso),
                                      "--eps=" + number(eps),
                                      "--topology=" + std::string(to_string(mode)),
                                      "--threads",
                                      std::to_string(threads)};
    };
    auto one_shot = [&](TopologyMode mode, double eps, int threads) {
      say(spec, "one shot from the raw file");
      Row r = row(spec, "one-shot", std::string(to_string(mode)).c_str(), eps, threads);
      extract_processes(r, extract_args(mode, eps, threads), work_ / "one.ply", true);
      r.note = "extraction and hierarchy; process: the whole run, raw file read and mesh written";
      finish(r);
    };
    for (const int t : thread_counts()) one_shot(TopologyMode::preserve, 0, t);
    // The same, quiet, into PLY and GLB: what the end-to-end targets time (the mesh written, no
    // summary line). Its triangles are the row above's, the same mesh.
    if (write_rate_ == 0) write_rate_ = durable_write_rate(work_);
    for (const char* format : {"ply", "glb"})
      for (const int t : thread_counts()) {
        say(spec, "one shot from the raw file, quiet");
        const std::string input = std::string("one-shot -q ") + format;
        Row r = row(spec, input.c_str(), "preserve", 0, t);
        extract_processes(r, extract_args(TopologyMode::preserve, 0, t), work_ / (std::string("quiet.") + format), true,
                          {}, true);
        if (const Row* loud = find_row(rows_, spec.name, "one-shot", "preserve", false, t))
          r.triangles = loud->triangles;
        r.note = "the whole process, quiet: raw file read, mesh written";
        finish(r);
      }
    // The same from the dataset's HDF5 copy beside the raw file, where the data has one (its
    // integers read as stored, its chunks decoded once: it should cost what the raw file does).
    const fs::path h5 = fs::path(raw).parent_path() / (std::string(spec.name) + ".h5");
    if (spec.file != nullptr && fs::exists(h5)) {
      say(spec, "one shot from the HDF5 file");
      std::vector<std::string> args = extract_args(TopologyMode::preserve, 0, threads_);
      args[1] = h5.string();
      Row r = row(spec, "one-shot h5", "preserve", 0, threads_);
      extract_processes(r, args, work_ / "h5.ply", true);
      r.note = "the whole process from the dataset's HDF5 copy, mesh written";
      finish(r);
    }
    one_shot(TopologyMode::none, d.coarse_eps, threads_);
    // The same coarse surface through a store: convert, then extract (its cache cold, the file in
    // the page cache as convert left it).
    say(spec, "convert + extract");
    Row r = row(spec, "convert+extract", "none", d.coarse_eps, threads_);
    const std::string other = (work_ / "again.isotope").string();
    const ChildRun conv = child({"convert", raw, other, "--threads", std::to_string(threads_), "-q"}, work_);
    const ChildRun ext =
        child({"extract", other, "--iso=" + number(spec.iso), "--eps=" + number(d.coarse_eps), "--topology=none",
               "--threads", std::to_string(threads_), "-q", "-o", (work_ / "two.ply").string()},
              work_);
    fs::remove(other);
    fs::remove(work_ / "two.ply");
    r.seconds = r.process_seconds = conv.seconds + ext.seconds;
    r.runs = 1;
    r.peak_rss = static_cast<uint64_t>(std::max(conv.max_rss_kb, ext.max_rss_kb)) << 10;
    r.triangles = rows_.back().triangles;
    r.note = "convert process + extract process";
    finish(r);
  }

  // Whole processes in alternation, the raw file in the page cache: convert and the one-shot coarse
  // surfaces (preserve and none) of this executable and of --reference, as many rounds each; and
  // convert on all threads against one.
  void versus_rows(const DatasetSpec& spec, DatasetResult& d, const std::string& raw) {
    const std::string self = self_executable(), threads = std::to_string(threads_);
    // A small volume's processes take tens of milliseconds, which one slow start moves by a third:
    // rounds until this executable's runs add up to a second (half with --quick), 15 at most.
    const int min_rounds = a_.quick ? 3 : 5, max_rounds = 15;
    const double min_seconds = a_.quick ? 0.5 : 1.0;
    // ARGS and OTHER_ARGS hold OUT where the output goes: each executable writes a file of its own.
    auto versus = [&](const std::string& what, const std::string& other, std::vector<std::string> args,
                      std::vector<std::string> other_args, const std::string& out) {
      DatasetResult::Versus v;
      v.what = what;
      v.threads = threads_;
      std::vector<double> ours, theirs;
      const std::string our_out = (work_ / ("ours-" + out)).string(), their_out = (work_ / ("theirs-" + out)).string();
      std::replace(args.begin(), args.end(), out, our_out);
      std::replace(other_args.begin(), other_args.end(), out, their_out);
      double total = 0;
      for (int i = 0; i < min_rounds || (total < min_seconds && i < max_rounds); ++i, ++v.rounds)
        for (int k = 0; k < 2; ++k) {  // each first in every other round
          const bool mine = (i + k) % 2 == 0;
          const ChildRun r = child_of(mine ? self : other, mine ? args : other_args, work_);
          (mine ? ours : theirs).push_back(r.seconds);
          if (mine) total += r.seconds;
          int64_t& rss = mine ? v.ours_rss_kb : v.theirs_rss_kb;
          rss = std::max(rss, r.max_rss_kb);
        }
      fs::remove(our_out);
      fs::remove(their_out);
      v.ours = median(ours);
      v.theirs = median(theirs);
      return v;
    };
    const std::vector<std::string> convert = {"convert", raw, "out.isotope", "--threads", threads, "-q"};
    if (!a_.reference.empty()) {
      say(spec, "beside the reference: convert");
      d.against_reference.push_back(versus("convert", a_.reference, convert, convert, "out.isotope"));
      for (const TopologyMode mode : {TopologyMode::preserve, TopologyMode::none}) {
        say(spec, "beside the reference: one shot, coarse");
        const std::vector<std::string> args = {"extract",
                                               raw,
                                               "--iso=" + number(spec.iso),
                                               "--eps=" + number(d.coarse_eps),
                                               "--topology=" + std::string(to_string(mode)),
                                               "--threads",
                                               threads,
                                               "-q",
                                               "-o",
                                               "out.ply"};
        d.against_reference.push_back(
            versus("one-shot " + std::string(to_string(mode)), a_.reference, args, args, "out.ply"));
      }
    }
    if (threads_ > 1) {
      say(spec, "convert on one thread and on all");
      std::vector<std::string> one = convert;
      one[4] = "1";
      d.convert_threads = versus("convert", self, convert, one, "out.isotope");
    }
  }

  // A triangle budget of 10% in simplify mode, delta chosen (ExtractOptions::auto_delta): the
  // preview a user of a noisy scan asks for first, from the cold store.
  json preview(const DatasetSpec& spec, const DatasetResult& d, const std::string& store) {
    say(spec, "a 10% budget in simplify mode");
    const int64_t budget = static_cast<int64_t>(kCoarseShare * static_cast<double>(d.full_triangles));
    evict_from_page_cache(store);
    const ChildRun c =
        child({"extract", store, "--iso=" + number(spec.iso), "--max-triangles", std::to_string(budget), "--topology",
               "simplify", "--threads", std::to_string(threads_), "-q", "-o", (work_ / "preview.ply").string(),
               "--report", (work_ / "preview.json").string(), "--compare-full"},
              work_);
    std::ifstream in(work_ / "preview.json");
    const auto report = nlohmann::json::parse(in);
    fs::remove(work_ / "preview.ply");
    fs::remove(work_ / "preview.json");
    json j = {{"budget", budget},
              {"triangles", report.at("triangles")},
              {"chosen_eps", report.at("chosen_eps")},
              {"chosen_delta", report.at("chosen_delta")},
              {"components", report.at("components")},
              {"full_components", report.at("compare_full").at("full").at("components")},
              {"changes", report.at("compare_full").at("summary")},
              {"extract_seconds", report.at("extract_seconds")},
              {"process_seconds", c.seconds}};
    return j;
  }

  // scikit-image's measure.marching_cubes on the same file, in python3 (Debian python3-skimage):
  // the time of loading the array and marching it (in the interpreter, imports excluded), and of
  // the whole process.
  void peer_rows(const DatasetSpec& spec, const DatasetResult& d, const std::string& raw) {
    say(spec, "scikit-image");
    const RawLayout layout = [&] {
      const auto named = parse_raw_name(raw);
      return named ? *named : RawLayout{d.dims, ScalarType::float32};
    }();
    const std::string script =
        "import os, sys, time, numpy\n"
        "from skimage import measure\n"
        "path, nx, ny, nz, dtype, iso, runs = sys.argv[1:]\n"
        "times = []\n"
        "for _ in range(int(runs)):\n"
        "    t = time.perf_counter()\n"
        "    a = numpy.fromfile(path, dtype=dtype).reshape(int(nz), int(ny), int(nx))\n"
        "    v, f, n, _ = measure.marching_cubes(a, float(iso))\n"
        "    times.append(time.perf_counter() - t)\n"
        "times.sort()\n"
        "print(times[len(times) // 2], len(f), os.environ.get('MALLOC_MMAP_THRESHOLD_', '-'))\n";
    const std::string dtype = layout.type == ScalarType::uint8     ? "uint8"
                              : layout.type == ScalarType::uint16  ? "<u2"
                              : layout.type == ScalarType::int16   ? "<i2"
                              : layout.type == ScalarType::float64 ? "<f8"
                                                                   : "<f4";
    const std::string runs = a_.quick ? "3" : "5";
    // Debian's interpreter, which python3-skimage installs into (a python3 earlier on PATH, from
    // pyenv or a virtual environment, may not have it).
    const std::string python = fs::exists("/usr/bin/python3") ? "/usr/bin/python3" : "python3";
    const ChildRun r =
        run_child(peer({python, "-c", script, raw, std::to_string(layout.dims[0]), std::to_string(layout.dims[1]),
                        std::to_string(layout.dims[2]), dtype, number(spec.iso), runs}),
                  (work_ / "peer.log").string());
    fs::remove(work_ / "peer.log");
    json j = {{"dataset", spec.name}};
    if (const auto line = peer_line(r, 2); !line) {
      j["skimage"] = nullptr;
      skipped_.push_back(std::string(spec.name) + " scikit-image: not run (" + why_not(r) +
                         "; scripts/install-deps.sh --tests installs python3-skimage)");
    } else {
      j["skimage"] = {{"load_and_march_seconds", line->numbers[0]},
                      {"triangles", static_cast<long long>(line->numbers[1])},
                      {"process_seconds", r.seconds},
                      {"malloc_mmap_threshold", line->threshold}};
    }
    j["flying_edges"] = flying_edges_run(spec, layout, raw, dtype, python, runs);
    peers_.push_back(j);
  }

  // A peer's command, run with the allocator policy this process's own extractions run under
  // (isotope::keep_freed_memory): without it each of a peer's runs faults fresh pages in
  // for its output, which on the reference machine made Flying Edges' march on embryo 180 ms on one
  // thread instead of 35 ms, while ours reuse their memory (docs/METHOD.md, "Fresh memory"). The
  // peer prints what it saw of it.
  static std::vector<std::string> peer(std::vector<std::string> argv) {
    argv.insert(argv.begin(), {"/usr/bin/env", "MALLOC_MMAP_THRESHOLD_=" + std::to_string(kKeptBlockBytes),
                               "MALLOC_TRIM_THRESHOLD_=" + std::to_string(kKeptTopBytes)});
    return argv;
  }

  // A peer's answer, its first line: COUNT numbers, then the MALLOC_MMAP_THRESHOLD_ it saw (peer()).
  // Nothing where it failed or said something else.
  struct PeerLine {
    std::vector<double> numbers;
    std::string threshold;
  };
  static std::optional<PeerLine> peer_line(const ChildRun& r, size_t count) {
    if (r.code != 0) return std::nullopt;
    std::istringstream in(r.output.substr(0, r.output.find('\n')));
    PeerLine line{std::vector<double>(count), {}};
    for (double& x : line.numbers)
      if (!(in >> x)) return std::nullopt;
    if (!(in >> line.threshold)) return std::nullopt;
    return line;
  }

  static std::string why_not(const ChildRun& r) {
    return r.code == -1 ? "python3 did not start" : r.output.substr(0, r.output.find('\n'));
  }

  // VTK's vtkFlyingEdges3D (Debian python3-vtk9) on the same array, loaded once: the march alone,
  // normals, gradients and scalars off, on one thread and on as many as ours use (vtkSMPTools, TBB
  // in Debian's build), beside our eps 0 from the hierarchy in memory. Null where it did not run.
  json flying_edges_run(const DatasetSpec& spec, const RawLayout& layout, const std::string& raw,
                        const std::string& dtype, const std::string& python, const std::string& runs) {
    say(spec, "VTK Flying Edges");
    const std::string script =
        "import os, sys, time, numpy, vtk\n"
        "from vtk.util import numpy_support\n"
        "path, nx, ny, nz, dtype, iso, runs, threads = sys.argv[1:]\n"
        "image = vtk.vtkImageData()\n"
        "image.SetDimensions(int(nx), int(ny), int(nz))\n"
        "values = numpy.fromfile(path, dtype=dtype)\n"
        "image.GetPointData().SetScalars(numpy_support.numpy_to_vtk(values, deep=False))\n"
        "medians = []\n"
        "for t in (1, int(threads)):\n"
        "    vtk.vtkSMPTools.Initialize(t)\n"
        "    times = []\n"
        "    for _ in range(int(runs)):\n"
        "        fe = vtk.vtkFlyingEdges3D()\n"
        "        fe.SetInputData(image)\n"
        "        fe.SetValue(0, float(iso))\n"
        "        fe.ComputeNormalsOff(); fe.ComputeGradientsOff(); fe.ComputeScalarsOff()\n"
        "        start = time.perf_counter()\n"
        "        fe.Update()\n"
        "        times.append(time.perf_counter() - start)\n"
        "    times.sort()\n"
        "    medians.append(times[len(times) // 2])\n"
        "print(medians[0], medians[1], fe.GetOutput().GetNumberOfPolys(),\n"
        "      os.environ.get('MALLOC_MMAP_THRESHOLD_', '-'))\n";
    const ChildRun r =
        run_child(peer({python, "-c", script, raw, std::to_string(layout.dims[0]), std::to_string(layout.dims[1]),
                        std::to_string(layout.dims[2]), dtype, number(spec.iso), runs, std::to_string(threads_)}),
                  (work_ / "peer.log").string());
    fs::remove(work_ / "peer.log");
    const auto line = peer_line(r, 3);
    if (!line) {
      skipped_.push_back(std::string(spec.name) + " VTK Flying Edges: not run (" + why_not(r) +
                         "; scripts/install-deps.sh --tests installs python3-vtk9)");
      return nullptr;
    }
    return {{"march_seconds_one_thread", line->numbers[0]},
            {"march_seconds_all_threads", line->numbers[1]},
            {"threads", threads_},
            {"triangles", static_cast<long long>(line->numbers[2])},
            {"malloc_mmap_threshold", line->threshold}};
  }

  // The paper's Table 1 on the same hierarchy: triangles per eps without and with topology
  // preservation, and our time for each on one thread.
  void paper_table1(const Hierarchy& mv) {
    for (size_t i = 0; i < std::size(kTable1Eps); ++i) {
      json j;
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

  const SuiteOptions& a_;
  fs::path work_;
  bool progress_;
  int threads_ = 1;
  Policy policy_, cold_policy_;
  double disk_rate_ = 0, write_rate_ = 0;
  std::map<int, double> baseline_seconds_;
  std::vector<Row> rows_;
  std::vector<DatasetResult> datasets_;
  json table1_ = json::array(), peers_ = json::array();
  std::vector<std::string> skipped_;
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

std::string ratio(double r) {
  char b[32];
  std::snprintf(b, sizeof b, "%.2fx", r);
  return b;
}

std::string mode_label(const Row& r) {
  if (r.mode != "simplify") return r.mode;
  char b[48];
  std::snprintf(b, sizeof b, "simplify %.3g", r.delta);
  return b;
}

void print_datasets(const std::vector<DatasetResult>& ds) {
  std::printf(
      "\nDatasets (coarse eps: the finest eps whose 'none' mesh has at most %.0f%% of the full triangles;\n"
      "simplify: interval weight, delta = %.0f%% of the value range; convert: a process on all threads with the\n"
      "default --memory-mb; its ceiling: zstd -3 on all threads over the values as float32, in memory)\n",
      kCoarseShare * 100, kDeltaOfRange * 100);
  std::printf("%-13s %-12s %8s %11s %10s %9s %8s %8s %9s %9s %8s %8s %9s\n", "dataset", "dims", "iso", "triangles",
              "coarse eps", "store MB", "/ raw", "(v2)", "build s", "convert s", "ceil s", "% ceil", "conv MB");
  for (const DatasetResult& d : ds) {
    const std::string dims =
        std::to_string(d.dims[0]) + "x" + std::to_string(d.dims[1]) + "x" + std::to_string(d.dims[2]);
    char pre[32] = "-", v2[32] = "-";
    if (d.preprocess_seconds >= 0) std::snprintf(pre, sizeof pre, "%.2f", d.preprocess_seconds);
    const auto old = kFormat2Ratio.find(d.spec->name);
    if (old != kFormat2Ratio.end()) std::snprintf(v2, sizeof v2, "%.3f", old->second);
    std::printf("%-13s %-12s %8g %11lld %10.4g %9s %8.3f %8s %9s %9.2f %8.3f %7.0f%% %9.0f\n", d.spec->name,
                dims.c_str(), static_cast<double>(d.spec->iso), static_cast<long long>(d.full_triangles), d.coarse_eps,
                mb(d.store_bytes).c_str(), static_cast<double>(d.store_bytes) / static_cast<double>(d.raw_bytes), v2,
                pre, d.convert_seconds, d.ceiling_seconds, 100 * d.ceiling_seconds / d.convert_seconds,
                d.convert_peak_mb);
  }
}

void print_rows(const std::vector<Row>& rows) {
  std::printf(
      "\nExtraction (median wall time; 'vs base': the baseline's time on as many threads over this row's.\n"
      "memory: the hierarchy in memory; store-warm: one brick cache kept across runs; store-cold: a new process\n"
      "with the store dropped from the page cache, the extraction it reports; one-shot: a process extracting\n"
      "from the raw file (ms: hierarchy and extraction; at eps 0 the file streamed in it); process ms: the\n"
      "whole process, mesh written; "
      "read MB: compressed bytes read from the store, per run)\n");
  std::printf("%-13s %-15s %-15s %9s %3s %10s %7s %9s %9s %9s %8s %8s %8s\n", "dataset", "input", "mode", "eps", "thr",
              "triangles", "% full", "ms", "proc ms", "tri/s", "vs base", "peak MB", "read MB");
  std::string last;
  for (const Row& r : rows) {
    if (r.dataset != last && !last.empty()) std::printf("\n");
    last = r.dataset;
    std::printf("%-13s %-15s %-15s %9.4g %3d %10lld %7.2f %9s %9s %9s %7.2fx %8s %8s\n", r.dataset.c_str(),
                r.input.c_str(), mode_label(r).c_str(), r.eps, r.threads, static_cast<long long>(r.triangles),
                100 * r.share, ms(r.seconds).c_str(), r.process_seconds > 0 ? ms(r.process_seconds).c_str() : "-",
                si(static_cast<double>(r.triangles) / r.seconds).c_str(), r.speedup, mb(r.peak_rss).c_str(),
                r.bytes_read ? mb(r.bytes_read).c_str() : "-");
  }
}

// The speed targets (and eps 0 at least the baseline's speed), each one line per dataset it applies to.
struct Target {
  std::string what, dataset, value;
  bool met = false;
};

// Flying Edges' row of a dataset in PEERS, or null where it did not run.
const json& flying_edges_of(const json& peers, const std::string& dataset) {
  static const json none;
  for (const auto& p : peers)
    if (p["dataset"] == dataset && p.contains("flying_edges")) return p["flying_edges"];
  return none;
}

// Our eps 0 on one thread and on all, from the hierarchy in memory (from a warm store where the
// suite keeps none in memory).
const Row* eps0_row(const std::vector<Row>& rows, const std::string& dataset, int threads) {
  const Row* r = find_row(rows, dataset, "memory", "preserve", false, threads);
  return r ? r : find_row(rows, dataset, "store-warm", "preserve", false, threads);
}

std::vector<Target> check_targets(const std::vector<Row>& rows, const std::vector<DatasetResult>& ds, const json& peers,
                                  int threads, double write_rate) {
  std::vector<Target> t;
  auto add = [&](const std::string& what, const std::string& dataset, const std::string& value, bool met) {
    t.push_back({what, dataset, value, met});
  };
  char buf[256];
  for (const DatasetResult& d : ds) {
    const std::string name = d.spec->name;
    const bool named = names_a_target(name);
    for (const int n : !named ? std::vector<int>{} : threads > 1 ? std::vector<int>{1, threads} : std::vector<int>{1}) {
      const Row* cold = find_row(rows, name, "store-cold", "none", true, n);
      const Row* cold0 = find_row(rows, name, "store-cold", "preserve", false, n);
      if (cold && cold->share <= kCoarseShare) {
        std::snprintf(buf, sizeof buf, "%s vs baseline, %d thread%s", ratio(cold->speedup).c_str(), n,
                      n == 1 ? "" : "s");
        add("coarse (<= 10%) from a cold store >= 10x the baseline", name, buf, cold->speedup >= 10);
        if (cold0) {
          const double x = cold0->seconds / cold->seconds;
          std::snprintf(buf, sizeof buf, "%s faster than eps 0 cold, %d thread%s", ratio(x).c_str(), n,
                        n == 1 ? "" : "s");
          add("coarse from a cold store >= 5x eps 0 from it", name, buf, x >= 5);
        }
        if (n == threads) {
          const double share = static_cast<double>(cold->bytes_read) / static_cast<double>(d.store_bytes);
          std::snprintf(buf, sizeof buf, "%.1f%% of the store (%s of %s MB)", 100 * share, mb(cold->bytes_read).c_str(),
                        mb(d.store_bytes).c_str());
          add("coarse reads at most 15% of the store", name, buf, share <= 0.15);
        }
      }
    }
    // Cold within 1.5x of its floor, every cold row.
    for (const Row& c : rows) {
      if (c.dataset != name || c.input != "store-cold" || c.floor_seconds <= 0) continue;
      const double x = c.seconds / c.floor_seconds;
      std::snprintf(buf, sizeof buf, "%s its floor (%s, eps %g, %d thr: %s ms; warm %s ms + %s MB read)",
                    ratio(x).c_str(), c.mode.c_str(), c.eps, c.threads, ms(c.seconds).c_str(),
                    ms(c.warm_seconds).c_str(), mb(c.bytes_read).c_str());
      add("cold store within 1.5x of its floor", name, buf, x <= 1.5);
    }
    // Warm within 1.25x of memory, every row that has both.
    for (const Row& w : rows) {
      if (w.dataset != name || w.input != "store-warm") continue;
      // From the runs in alternation, taken for every case of a dataset with memory rows.
      const DatasetResult::Paired* p = d.paired(w.mode, w.eps > 0, w.threads);
      if (!p) continue;
      const double x = p->ratio;
      std::snprintf(buf, sizeof buf, "%s memory (%s %s, eps %g, %d thr; median of %d pairs in alternation)",
                    ratio(x).c_str(), w.mode.c_str(), w.eps > 0 ? "coarse" : "eps 0", w.eps, w.threads, p->pairs);
      add("warm store within 1.25x of memory", name, buf, x <= 1.25);
    }
    // Coarse never slower than eps 0, warm and cold: every row of a coarse surface (at most 10%
    // of the triangles; preserve keeps more on noisy data, and is then not a coarse surface).
    for (const Row& c : rows) {
      if (c.dataset != name || (c.input != "store-warm" && c.input != "store-cold") || c.eps == 0 ||
          c.share > kCoarseShare + 0.005)
        continue;
      const Row* z = find_row(rows, name, c.input, "preserve", false, c.threads);
      if (!z) continue;
      std::snprintf(buf, sizeof buf, "%s, %s, %d thr: coarse %s ms, eps 0 %s ms", c.input.c_str(), c.mode.c_str(),
                    c.threads, ms(c.seconds).c_str(), ms(z->seconds).c_str());
      add("coarse never slower than eps 0", name, buf, c.seconds <= z->seconds);
    }
    // One shot at eps 0 against scikit-image (load included for both: our whole process).
    const Row* shot = find_row(rows, name, "one-shot", "preserve", false, threads);
    if (!named) shot = nullptr;
    for (const auto& p : peers)
      if (p["dataset"] == name && !p["skimage"].is_null() && shot) {
        const double theirs = p["skimage"]["load_and_march_seconds"].get<double>();
        std::snprintf(buf, sizeof buf, "our process %s ms (extraction %s ms) vs scikit-image load + march %s ms",
                      ms(shot->process_seconds).c_str(), ms(shot->seconds).c_str(), ms(theirs).c_str());
        add("one-shot eps 0 at least as fast as scikit-image", name, buf, shot->process_seconds <= theirs);
      }
    // Coarse one-shot pays only for what it needs: against convert + extract.
    const Row* coarse_shot = find_row(rows, name, "one-shot", "none", true, threads);
    const Row* two = find_row(rows, name, "convert+extract", "none", true, threads);
    if (named && coarse_shot && two) {
      std::snprintf(buf, sizeof buf, "one shot %s ms, convert + extract %s ms",
                    ms(coarse_shot->process_seconds).c_str(), ms(two->process_seconds).c_str());
      add("coarse one-shot cheaper than convert + extract", name, buf,
          coarse_shot->process_seconds < two->process_seconds);
    }
    // eps 0 in the process, from the array in memory: all threads against one.
    const Row* in1 = eps0_row(rows, name, 1);
    const Row* in_all = eps0_row(rows, name, threads);
    if (named && in1 && in_all && threads > 1) {
      const double x = in1->seconds / in_all->seconds;
      std::snprintf(buf, sizeof buf, "%s (%s ms on 1 thread, %s ms on %d)", ratio(x).c_str(), ms(in1->seconds).c_str(),
                    ms(in_all->seconds).c_str(), threads);
      add("eps 0 in process: all threads >= 1.85x one", name, buf, x >= 1.85);
    }
    // End to end, quiet, the mesh written: all threads against one, and against the extraction in
    // memory (the rest is the read and the write, which should overlap it).
    for (const char* format : {"ply", "glb"}) {
      const std::string input = std::string("one-shot -q ") + format;
      const Row* q1 = find_row(rows, name, input, "preserve", false, 1);
      const Row* q_all = find_row(rows, name, input, "preserve", false, threads);
      if (named && q1 && q_all && threads > 1) {
        const double x = q1->process_seconds / q_all->process_seconds;
        std::snprintf(buf, sizeof buf, "%s, %s (%s ms on 1 thread, %s ms on %d)", format, ratio(x).c_str(),
                      ms(q1->process_seconds).c_str(), ms(q_all->process_seconds).c_str(), threads);
        add("eps 0 end to end, quiet: all threads >= 1.75x one", name, buf, x >= 1.75);
      }
      if (named && q_all && in_all) {
        // Beside it, what a process that writes the mesh only once the march is done should take:
        // the extraction in memory, then the mesh's bytes written to the disk at its measured rate.
        // An estimate, not a bound: the writer starts the disk on its first bytes while it still
        // encodes the rest (embryo's PLY has come in under it).
        const double x = q_all->process_seconds / in_all->seconds;
        const double written = static_cast<double>(q_all->bytes_written);
        std::snprintf(buf, sizeof buf,
                      "%s, %s (process %s ms, in memory %s ms, %d thr; march, then the mesh at the disk's rate: "
                      "%s ms, %.0f MB at %.0f MB/s)",
                      format, ratio(x).c_str(), ms(q_all->process_seconds).c_str(), ms(in_all->seconds).c_str(),
                      threads, ms(in_all->seconds + written / write_rate).c_str(), written / 1e6, write_rate / 1e6);
        add("one-shot eps 0, quiet, within 1.25x the extraction in memory", name, buf, x <= 1.25);
      }
    }
    // Against another commit's executable: convert and the one-shot coarse surfaces, on every
    // volume the speed targets name and every shared one (a volume of a file).
    for (const DatasetResult::Versus& v : d.against_reference) {
      if (!named && d.spec->file == nullptr) continue;
      const double x = v.theirs / v.ours;
      std::snprintf(buf, sizeof buf, "%s (%s: %s ms, the reference's %s ms, %d thr)", ratio(x).c_str(), v.what.c_str(),
                    ms(v.ours).c_str(), ms(v.theirs).c_str(), v.threads);
      add(v.what == "convert" ? "convert >= 3x the reference's speed" : "one-shot coarse >= 3x the reference's speed",
          name, buf, x >= 3);
    }
    if (const DatasetResult::Versus& v = d.convert_threads; named && v.rounds > 0) {
      const double x = v.theirs / v.ours;
      std::snprintf(buf, sizeof buf, "%s (%s ms on 1 thread, %s ms on %d)", ratio(x).c_str(), ms(v.theirs).c_str(),
                    ms(v.ours).c_str(), v.threads);
      add("convert: all threads >= 1.8x one", name, buf, x >= 1.8);
    }
    // Convert at 50% of its ceiling; the store no larger than format 2's.
    if (named) {
      std::snprintf(buf, sizeof buf, "%.0f%% (%.2f s against %.2f s)", 100 * d.ceiling_seconds / d.convert_seconds,
                    d.convert_seconds, d.ceiling_seconds);
      add("convert >= 50% of the zstd ceiling", name, buf, d.ceiling_seconds / d.convert_seconds >= 0.5);
    }
    const auto old = kFormat2Ratio.find(name);
    if (old != kFormat2Ratio.end()) {
      const double now = static_cast<double>(d.store_bytes) / static_cast<double>(d.raw_bytes);
      std::snprintf(buf, sizeof buf, "%.3f of the raw input (format 2: %.3f)", now, old->second);
      add("store no larger than format 2's", name, buf, now <= old->second * 1.005);
    }
    // Per triangle, eps 0 on one thread, at least Flying Edges' rate on the same array.
    const json& fe = flying_edges_of(peers, name);
    const Row* e1 = eps0_row(rows, name, 1);
    if (named && !fe.is_null() && e1) {
      const double theirs =
          static_cast<double>(fe["triangles"].get<int64_t>()) / fe["march_seconds_one_thread"].get<double>();
      const double ours = static_cast<double>(e1->triangles) / e1->seconds;
      std::snprintf(buf, sizeof buf, "ours %s triangles/s (%s ms, %s) vs VTK %s (%s ms, %s): %s", si(ours).c_str(),
                    ms(e1->seconds).c_str(), si(static_cast<double>(e1->triangles)).c_str(), si(theirs).c_str(),
                    ms(fe["march_seconds_one_thread"].get<double>()).c_str(),
                    si(static_cast<double>(fe["triangles"].get<int64_t>())).c_str(), ratio(ours / theirs).c_str());
      add("eps 0 per triangle at least Flying Edges' rate, one thread", name, buf, ours >= theirs);
    }
    // eps 0 gives the baseline's mesh, and at least its speed.
    for (const Row& r : rows)
      if (r.dataset == name && r.eps == 0 && r.mode != "baseline" && (r.input == "memory" || r.input == "store-warm")) {
        std::snprintf(buf, sizeof buf, "%s, %s, %d thr: %s", r.input.c_str(), r.mode.c_str(), r.threads,
                      ratio(r.speedup).c_str());
        add("eps 0 at least as fast as the baseline, same triangles", name, buf, r.speedup >= 1 && r.share == 1.0);
      }
  }
  // Grouped by target, in the order of their first appearance.
  std::vector<std::string> order;
  for (const Target& x : t)
    if (std::find(order.begin(), order.end(), x.what) == order.end()) order.push_back(x.what);
  std::stable_sort(t.begin(), t.end(), [&](const Target& a, const Target& b) {
    return std::find(order.begin(), order.end(), a.what) < std::find(order.begin(), order.end(), b.what);
  });
  return t;
}

json print_targets(const std::vector<Target>& targets) {
  std::printf("\nTargets (each measured in this run)\n");
  json out = json::array();
  std::string last;
  int met = 0;
  for (const Target& t : targets) {
    if (t.what != last) std::printf("  %s\n", t.what.c_str());
    last = t.what;
    std::printf("    %-7s %-13s %s\n", t.met ? "met" : "MISSED", t.dataset.c_str(), t.value.c_str());
    out.push_back({{"target", t.what}, {"dataset", t.dataset}, {"value", t.value}, {"met", t.met}});
    met += t.met;
  }
  std::printf("  %d of %zu met\n", met, targets.size());
  return out;
}

json flying_edges(const json& peers, const std::vector<Row>& rows, int threads) {
  std::printf(
      "\nVTK Flying Edges on the same array (run here: python3-vtk9's vtkFlyingEdges3D, the march alone, normals\n"
      "off; marching cubes: about 2.7x fewer triangles than our tetrahedra), beside our eps 0 in memory\n");
  const std::string all = std::to_string(threads) + "t";
  std::printf("%-13s %10s %10s %10s %12s %16s %12s %16s %14s\n", "dataset", "VTK 1t ms", ("VTK " + all + " ms").c_str(),
              "VTK tri", "VTK tri/s 1t", "ours eps 0 1t", "ours tri/s 1t", ("ours eps 0 " + all).c_str(),
              "ours coarse");
  json out = json::array();
  for (const auto& p : peers) {
    const std::string name = p["dataset"];
    const json& fe = flying_edges_of(peers, name);
    if (fe.is_null()) {
      std::printf("%-13s %10s\n", name.c_str(), "not run");
      continue;
    }
    const Row* e1 = eps0_row(rows, name, 1);
    const Row* en = eps0_row(rows, name, threads);
    const Row* c = find_row(rows, name, "memory", "none", true, threads);
    auto cell = [](const Row* r) {
      return r ? ms(r->seconds) + " (" + si(static_cast<double>(r->triangles)) + ")" : std::string("-");
    };
    const double one = fe["march_seconds_one_thread"].get<double>();
    const auto triangles = fe["triangles"].get<int64_t>();
    std::printf("%-13s %10s %10s %10s %12s %16s %12s %16s %14s\n", name.c_str(), ms(one).c_str(),
                ms(fe["march_seconds_all_threads"].get<double>()).c_str(), si(static_cast<double>(triangles)).c_str(),
                si(static_cast<double>(triangles) / one).c_str(), cell(e1).c_str(),
                e1 ? si(static_cast<double>(e1->triangles) / e1->seconds).c_str() : "-", cell(en).c_str(),
                cell(c).c_str());
    auto row_ms = [](const Row* r) { return r ? json(r->seconds * 1e3) : json(); };
    out.push_back({{"dataset", name},
                   {"vtk", fe},
                   {"ours",
                    {{"eps0_1_thread_ms", row_ms(e1)},
                     {"eps0_all_threads_ms", row_ms(en)},
                     {"triangles", e1 ? json(e1->triangles) : json()},
                     {"coarse_none_all_threads_ms", row_ms(c)}}}});
  }
  return out;
}

void print_peers(const json& peers, const std::vector<Row>& rows, int threads) {
  std::printf(
      "\nscikit-image measure.marching_cubes on the same file (run here: python3 -c, numpy.fromfile and "
      "marching_cubes\n"
      "timed in the interpreter, imports excluded; process: the whole python3 run), beside our one-shot process\n");
  std::printf("%-13s %14s %12s %14s %16s %16s\n", "dataset", "skimage ms", "skimage tri", "skimage proc",
              "ours proc 1t", ("ours proc " + std::to_string(threads) + "t").c_str());
  for (const auto& p : peers) {
    const std::string name = p["dataset"];
    const Row* one = find_row(rows, name, "one-shot", "preserve", false, 1);
    const Row* all = find_row(rows, name, "one-shot", "preserve", false, threads);
    if (p["skimage"].is_null()) {
      std::printf("%-13s %14s\n", name.c_str(), "not run");
      continue;
    }
    std::printf("%-13s %14s %12s %14s %16s %16s\n", name.c_str(), ms(p["skimage"]["load_and_march_seconds"]).c_str(),
                si(p["skimage"]["triangles"].get<double>()).c_str(), ms(p["skimage"]["process_seconds"]).c_str(),
                one ? ms(one->process_seconds).c_str() : "-", all ? ms(all->process_seconds).c_str() : "-");
  }
}

void print_previews(const std::vector<DatasetResult>& ds) {
  for (const DatasetResult& d : ds) {
    if (d.preview.is_null()) continue;
    const json& p = d.preview;
    std::printf(
        "\nA 10%% preview of %s in simplify mode, delta chosen (--max-triangles %lld --topology simplify, cold "
        "store):\n"
        "  %lld triangles, eps %g, delta %g; %lld of %lld components kept; extraction %s ms, process %s ms\n"
        "  against full resolution: %s\n",
        d.spec->name, static_cast<long long>(p["budget"].get<int64_t>()),
        static_cast<long long>(p["triangles"].get<int64_t>()), p["chosen_eps"].get<double>(),
        p["chosen_delta"].get<double>(), static_cast<long long>(p["components"].get<int64_t>()),
        static_cast<long long>(p["full_components"].get<int64_t>()), ms(p["extract_seconds"].get<double>()).c_str(),
        ms(p["process_seconds"].get<double>()).c_str(), p["changes"].dump().c_str());
  }
}

// Whole processes of this executable beside --reference's, and convert on one thread beside all.
void print_versus(const std::vector<DatasetResult>& ds, const std::string& reference, const std::string& version) {
  bool any = false;
  for (const DatasetResult& d : ds) any = any || !d.against_reference.empty() || d.convert_threads.rounds > 0;
  if (!any) return;
  std::printf("\nWhole processes in alternation, the raw file in the page cache (median of the rounds)%s%s%s\n",
              reference.empty() ? "" : "; the reference: ", reference.c_str(),
              version.empty() ? "" : (" (" + version + ")").c_str());
  std::printf("%-13s %-18s %4s %10s %10s %7s %8s %8s\n", "dataset", "case", "thr", "ours ms", "theirs ms", "ratio",
              "ours MB", "their MB");
  auto line = [](const DatasetResult& d, const DatasetResult::Versus& v, const std::string& what) {
    std::printf("%-13s %-18s %4d %10s %10s %7s %8.0f %8.0f\n", d.spec->name, what.c_str(), v.threads,
                ms(v.ours).c_str(), ms(v.theirs).c_str(), ratio(v.theirs / v.ours).c_str(),
                static_cast<double>(v.ours_rss_kb) / 1024, static_cast<double>(v.theirs_rss_kb) / 1024);
  };
  for (const DatasetResult& d : ds) {
    for (const DatasetResult::Versus& v : d.against_reference) line(d, v, v.what);
    if (d.convert_threads.rounds > 0) line(d, d.convert_threads, "convert vs 1 thr");
  }
}

void print_table1(const json& t) {
  if (t.empty()) return;
  std::printf("\nPaper's Table 1 (algebraic function 65^3, iso 0, error indicator: bound; one thread)\n");
  std::printf("%-6s | %-16s | %-30s | %-30s\n", "eps", "paper: w/o  with", "ours without: triangles  ms",
              "ours with: triangles  ms");
  for (const auto& r : t) {
    std::printf("%-6s | %7d %8d | %20lld %8s | %20lld %8s\n", r["eps"].get<std::string>().c_str(),
                r["paper"]["without"].get<int>(), r["paper"]["with"].get<int>(),
                r["without"]["triangles"].get<long long>(), ms(r["without"]["seconds"].get<double>()).c_str(),
                r["with"]["triangles"].get<long long>(), ms(r["with"]["seconds"].get<double>()).c_str());
  }
  std::printf(
      "The paper's eps scale is not stated (docs/METHOD.md): compare the shape of the columns. Its speed claim\n"
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

json rows_json(const std::vector<Row>& rows) {
  json out = json::array();
  for (const Row& r : rows) {
    json j = {{"dataset", r.dataset}, {"input", r.input}, {"mode", r.mode}, {"eps", r.eps}};
    if (r.mode == "simplify") j["delta"] = r.delta;
    j.update({{"threads", r.threads},
              {"triangles", r.triangles},
              {"share_of_full", r.share},
              {"seconds", r.seconds},
              {"runs", r.runs},
              {"triangles_per_second", static_cast<double>(r.triangles) / r.seconds},
              {"speedup_vs_baseline", r.speedup},
              {"peak_rss_bytes", r.peak_rss},
              {"bytes_read", r.bytes_read}});
    if (r.process_seconds > 0) j["process_seconds"] = r.process_seconds;
    if (r.bytes_written > 0) j["bytes_written"] = r.bytes_written;
    if (r.floor_seconds > 0) j.update({{"warm_seconds", r.warm_seconds}, {"floor_seconds", r.floor_seconds}});
    out.push_back(j);
  }
  return out;
}

json datasets_json(const std::vector<DatasetResult>& ds) {
  json out = json::array();
  for (const DatasetResult& d : ds) {
    json j = {{"name", d.spec->name},
              {"description", d.spec->description},
              {"dims", d.dims},
              {"iso", d.spec->iso},
              {"value_range", {d.value_min, d.value_max}},
              {"full_triangles", d.full_triangles},
              {"coarse_eps", d.coarse_eps},
              {"delta", d.delta}};
    j["preprocess_seconds"] = d.preprocess_seconds >= 0 ? json(d.preprocess_seconds) : json();
    j["convert_seconds"] = d.convert_seconds;
    j["convert_voxels_per_second"] = static_cast<double>(d.voxels()) / d.convert_seconds;
    j["convert_peak_rss_mb"] = d.convert_peak_mb;
    j["convert_ceiling_seconds"] = d.ceiling_seconds;
    j["store_bytes"] = d.store_bytes;
    j["raw_bytes"] = d.raw_bytes;
    if (!d.preview.is_null()) j["simplify_preview"] = d.preview;
    for (const DatasetResult::Paired& p : d.warm_over_memory)
      j["warm_over_memory"].push_back(
          {{"mode", p.mode}, {"coarse", p.coarse}, {"threads", p.threads}, {"ratio", p.ratio}, {"pairs", p.pairs}});
    auto versus = [](const DatasetResult::Versus& v, const char* theirs) {
      return json{{"case", v.what},
                  {"threads", v.threads},
                  {"seconds", v.ours},
                  {std::string(theirs) + "_seconds", v.theirs},
                  {"ratio", v.theirs / v.ours},
                  {"peak_rss_mb", static_cast<double>(v.ours_rss_kb) / 1024},
                  {std::string(theirs) + "_peak_rss_mb", static_cast<double>(v.theirs_rss_kb) / 1024},
                  {"rounds", v.rounds}};
    };
    for (const DatasetResult::Versus& v : d.against_reference) j["against_reference"].push_back(versus(v, "reference"));
    if (d.convert_threads.rounds > 0) j["convert_threads"] = versus(d.convert_threads, "one_thread");
    out.push_back(j);
  }
  return out;
}

// ---- The large-volume row --------------------------------------------------------------------

// A generated N^3 uint8 volume (the paper's algebraic function over [-2, 1.5] onto 0..255, written
// slab by slab: it is larger than memory as float), converted with --memory-mb 1024 and extracted
// coarse with --cache-mb 256 from the cold store, beside the surface at eps 0 from the cold raw
// file, each a process measured whole.
int run_scale(const SuiteOptions& a, const fs::path& work, bool progress) {
  const int64_t n = a.scale_size;
  const std::string raw =
      (work / ("algebraic_" + std::to_string(n) + "x" + std::to_string(n) + "x" + std::to_string(n) + "_uint8.raw"))
          .string();
  if (progress) std::fprintf(stderr, "isotope: bench --scale: writing %s\n", raw.c_str());
  const auto start = std::chrono::steady_clock::now();
  {
    AtomicFile out(raw);
    std::vector<uint8_t> slab(static_cast<size_t>(n * n));
    const double h = 2.0 / static_cast<double>(n - 1);
    for (int64_t z = 0; z < n; ++z) {
      if (InterruptGuard::interrupted()) throw IoError("interrupted");
      const double pz = -1 + h * static_cast<double>(z);
      parallel_for(int64_t{0}, n, [&](int64_t y) {
        const double py = -1 + h * static_cast<double>(y);
        for (int64_t x = 0; x < n; ++x) {
          const double px = -1 + h * static_cast<double>(x);
          const double f = algebraic_function(px, py, pz);
          slab[static_cast<size_t>(y * n + x)] =
              static_cast<uint8_t>(std::lround(std::clamp((f + 2) / 3.5, 0.0, 1.0) * 255));
        }
      });
      out.write(slab.data(), slab.size());
    }
    out.commit();
  }
  const double write_seconds = seconds_since(start);
  const std::string iso = "145.5";  // f = 0 lies at code 145.7
  const std::string store = (work / "scale.isotope").string();
  if (progress) std::fprintf(stderr, "isotope: bench --scale: converting\n");
  evict_from_page_cache(raw);
  const ChildRun conv = child({"convert", raw, store, "--memory-mb", "1024", "-q"}, work);
  // The full-resolution alternative: the surface at eps 0 in one process from the cold raw file,
  // with no store (how a user compares a coarse surface with what it stands for), the file
  // streamed a window of layers at a time (docs/METHOD.md, "eps = 0 from a file").
  if (progress) std::fprintf(stderr, "isotope: bench --scale: extracting at eps 0 from the raw file\n");
  evict_from_page_cache(raw);
  const ChildRun full = child(
      {"extract", raw, "--iso", iso, "--eps", "0", "--topology", "none", "-o", (work / "scale-full.ply").string()},
      work);
  const Summary full_summary = parse_summary(full.output);
  fs::remove(work / "scale-full.ply");
  fs::remove(raw);
  const uint64_t store_bytes = fs::file_size(store);
  if (progress) std::fprintf(stderr, "isotope: bench --scale: extracting\n");
  // Timed as a user runs it, with the summary line and no report (whose per-component measures
  // would be timed with it: Summary); then once more with a report, untimed, for what it read.
  const std::vector<std::string> extract = {"extract",         store,     "--iso",      iso,
                                            "--max-triangles", "1000000", "--topology", "none",
                                            "--cache-mb",      "256",     "-o",         (work / "scale.ply").string()};
  evict_from_page_cache(store);
  const ChildRun ext = child(extract, work);
  const Summary summary = parse_summary(ext.output);
  std::vector<std::string> reported = extract;
  reported.insert(reported.end(), {"-q", "--report", (work / "scale.json").string()});
  evict_from_page_cache(store);
  child(reported, work);
  std::ifstream in(work / "scale.json");
  const auto report = nlohmann::json::parse(in);
  std::printf("isotope bench --scale: %s, %u hardware threads\n", cpu_model().c_str(),
              std::thread::hardware_concurrency());
  std::printf("volume       %lld^3 uint8 (%.2f GB), the algebraic function; written in %.1f s\n",
              static_cast<long long>(n), static_cast<double>(n * n * n) / 1e9, write_seconds);
  std::printf(
      "convert      --memory-mb 1024: %.1f s (%.1f M voxels/s), peak RSS %.0f MB, store %.2f GB (%.3f of the raw)\n",
      conv.seconds, static_cast<double>(n * n * n) / conv.seconds / 1e6, static_cast<double>(conv.max_rss_kb) / 1024,
      static_cast<double>(store_bytes) / 1e9, static_cast<double>(store_bytes) / static_cast<double>(n * n * n));
  std::printf(
      "extract      --cache-mb 256, coarse (at most 1M triangles, mode none, eps %g), cold store: %.2f s process,\n"
      "             %.2f s extraction, %lld triangles, peak RSS %.0f MB, %.1f MB read (%.2f%% of the store)\n",
      report.at("chosen_eps").get<double>(), ext.seconds, summary.extract_seconds,
      static_cast<long long>(summary.triangles), static_cast<double>(ext.max_rss_kb) / 1024,
      report.at("bytes_read").get<double>() / 1e6,
      100 * report.at("bytes_read").get<double>() / static_cast<double>(store_bytes));
  std::printf(
      "one-shot     eps 0 from the cold raw file, mode none: %.2f s process, %.2f s extraction, %lld triangles,\n"
      "             peak RSS %.0f MB\n",
      full.seconds, full_summary.extract_seconds, static_cast<long long>(full_summary.triangles),
      static_cast<double>(full.max_rss_kb) / 1024);
  const json one_shot_full = json{{"process_seconds", full.seconds},
                                  {"extract_seconds", full_summary.extract_seconds},
                                  {"triangles", full_summary.triangles},
                                  {"peak_rss_mb", static_cast<double>(full.max_rss_kb) / 1024}};
  if (!a.json.empty())
    write_json_file(json{{"scale_size", n},
                         {"write_seconds", write_seconds},
                         {"convert",
                          {{"seconds", conv.seconds},
                           {"peak_rss_mb", static_cast<double>(conv.max_rss_kb) / 1024},
                           {"memory_mb", 1024},
                           {"store_bytes", store_bytes}}},
                         {"one_shot_full", one_shot_full},
                         {"extract",
                          {{"process_seconds", ext.seconds},
                           {"extract_seconds", summary.extract_seconds},
                           {"peak_rss_mb", static_cast<double>(ext.max_rss_kb) / 1024},
                           {"cache_mb", 256},
                           {"report", report}}}},
                    a.json);
  return 0;
}

// ---- The command -----------------------------------------------------------------------------

std::vector<const DatasetSpec*> selected(const SuiteOptions& a) {
  std::vector<const DatasetSpec*> out;
  for (const std::string& name : a.datasets) {
    const auto it = std::find_if(suite().begin(), suite().end(), [&](const DatasetSpec& s) { return name == s.name; });
    if (it == suite().end()) {
      std::string names;
      for (const DatasetSpec& s : suite()) names += std::string(names.empty() ? "" : ", ") + s.name;
      throw OptionError("dataset", "unknown dataset '" + name + "' (one of " + names + ")");
    }
  }
  for (const DatasetSpec& s : suite()) {
    const bool named = std::find(a.datasets.begin(), a.datasets.end(), s.name) != a.datasets.end();
    if (a.datasets.empty() ? (s.quick || !a.quick) : named) out.push_back(&s);
  }
  return out;
}

}  // namespace

int run_suite(const SuiteOptions& a) {
  // Before this process holds any volume: the peak memory of each process it times is then the
  // process's own (spawn_children_from_here).
  spawn_children_from_here();
  const std::vector<const DatasetSpec*> specs = selected(a);
  if (!a.json.empty()) AtomicFile check(a.json);  // a bad --json directory fails now, not after the suite
  const bool progress = progress_enabled(a.quiet);
  // The stores' folder, removed with them when the command ends, however it ends.
  const TempDir work(fs::path(a.work_dir.empty() ? fs::temp_directory_path().string() : a.work_dir) /
                     ("isotope-bench-" + std::to_string(::getpid())));
  const InterruptGuard guard;  // Ctrl-C stops between runs, and the work directory is removed
  if (a.scale) return run_scale(a, work.path(), progress);
  // The data must be there: a missing volume is an error, not a row silently left out.
  for (const DatasetSpec* spec : specs)
    if (spec->file && !fs::is_regular_file(fs::path(a.data) / spec->file))
      throw IoError((fs::path(a.data) / spec->file).string() +
                    ": not found (pass --data DIR, or --dataset to choose others)");
  const std::string reference = a.reference.empty() ? "" : reference_version(a.reference, work.path());
  Suite suite(a, work.path(), progress);
  const auto start = std::chrono::steady_clock::now();
  for (const DatasetSpec* spec : specs) {
    Volume volume;
    std::string raw;
    if (spec->file) {
      raw = (fs::path(a.data) / spec->file).string();
      volume = read_volume(VolumeSpec{raw, std::nullopt, std::nullopt});
    } else {
      if (progress) std::fprintf(stderr, "\r\033[Kisotope: bench %s: generating", spec->name);
      {
        const ThreadCap cap(suite.threads());
        volume = spec->generate();
      }
      // A float32 raw file for the processes (convert, one shot, scikit-image); unit spacing,
      // as every raw input has.
      raw = (work.path() / (std::string(spec->name) + "_" + std::to_string(volume.dims[0]) + "x" +
                            std::to_string(volume.dims[1]) + "x" + std::to_string(volume.dims[2]) + "_float32.raw"))
                .string();
      write_raw(volume, raw, ScalarType::float32);
      volume.spacing = {1, 1, 1};
      volume.origin = {0, 0, 0};
    }
    if (InterruptGuard::interrupted()) throw IoError("interrupted");
    suite.run(*spec, volume, raw);
    if (!spec->file) fs::remove(raw);
  }
  if (progress) std::fprintf(stderr, "\r\033[K");
  const double total = seconds_since(start);

  std::printf("isotope bench%s: %s, %u hardware threads, %d used; %.1f s\n", a.quick ? " --quick" : "",
              cpu_model().c_str(), std::thread::hardware_concurrency(), suite.threads(), total);
  if (suite.disk_rate() > 0)
    std::printf("disk: %.0f MB/s sequential (256 MB read in 1 MB reads, dropped from the page cache first)\n",
                suite.disk_rate() / 1e6);
  if (suite.write_rate() > 0)
    std::printf("disk: %.0f MB/s written as a mesh is (64 MB as a region in pieces of %zu MB, flushed, renamed)\n",
                suite.write_rate() / 1e6, AtomicFile::kRegionPieceBytes >> 20);
  print_datasets(suite.datasets());
  print_rows(suite.rows());
  print_peers(suite.peers(), suite.rows(), suite.threads());
  print_previews(suite.datasets());
  print_versus(suite.datasets(), a.reference, reference);
  const json fe = flying_edges(suite.peers(), suite.rows(), suite.threads());
  print_table1(suite.table1());
  const std::vector<Target> targets =
      check_targets(suite.rows(), suite.datasets(), suite.peers(), suite.threads(), suite.write_rate());
  const json target_json = print_targets(targets);
  for (const std::string& s : suite.skipped()) std::printf("skipped: %s\n", s.c_str());

  if (!a.json.empty()) {
    json j;
    j["isotope_version"] = ISOTOPE_VERSION_STRING;
    j["suite"] = a.quick ? "quick" : "full";
    j["machine"] = {{"cpu", cpu_model()},
                    {"hardware_threads", std::thread::hardware_concurrency()},
                    {"threads", suite.threads()},
                    {"disk_read_bytes_per_second", suite.disk_rate()},
                    {"disk_write_bytes_per_second", suite.write_rate()}};
    j["policy"] = {{"min_runs", suite.policy().min_runs},
                   {"max_runs", suite.policy().max_runs},
                   {"min_seconds", suite.policy().min_seconds},
                   {"statistic", "median"},
                   {"cache_mb", a.cache_mb}};
    j["seconds"] = total;
    if (!a.reference.empty()) j["reference"] = {{"executable", a.reference}, {"version", reference}};
    j["datasets"] = datasets_json(suite.datasets());
    j["rows"] = rows_json(suite.rows());
    j["targets"] = target_json;
    j["peers"] = suite.peers();
    j["flying_edges"] = fe;
    j["paper_table1"] = suite.table1();
    j["paper_triangles_per_second"] = {{"one_processor", kPaperTrianglesPerSecondOne},
                                       {"multiprocessor", kPaperTrianglesPerSecondMany}};
    j["skipped"] = suite.skipped();
    write_json_file(j, a.json);
  }
  return 0;
}

}  // namespace isotope::bench
