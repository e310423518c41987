// Google Benchmark suite: adaptive extraction against the full-resolution baseline, the same
// extraction paged out of a store through a brick cache, the decoding of one brick, preprocessing,
// and the critical-pattern table. Every threaded benchmark runs at each cap of thread_counts().
// How to build, run and compare: bench/README.md (and how the JSON output becomes ratios against
// the baseline: "JSON output and ratios against the baseline").
//
// Every input (volume, preprocessed hierarchy, store) is built once per process in a
// function-local static, outside any timed loop. Times are wall-clock (UseRealTime) because preprocessing runs
// on oneTBB's worker threads, whose CPU time the main thread's clock would not see.
#include <benchmark/benchmark.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <array>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "bench/bench_support.h"
#include "engine/extract/extract_drivers.h"
#include "engine/extract/options.h"
#include "engine/hierarchy/banded_build.h"
#include "engine/hierarchy/critical_table.h"
#include "engine/hierarchy/diamond.h"
#include "engine/hierarchy/multires_volume.h"
#include "engine/hierarchy/record.h"
#include "engine/synthetic/fields.h"
#include "io/store/brick_cache.h"
#include "io/store/paged_volume.h"
#include "io/store/store_format.h"
#include "io/store/store_reader.h"
#include "io/store/store_writer.h"
#include "io/volume/box_reader.h"
#include "io/volume/raw_reader.h"
#include "isotope/mesh.h"
#include "isotope/volume.h"

namespace {

using isotope::ExtractOptions;
using isotope::ExtractStats;
using isotope::Mesh;
using isotope::MultiresVolume;
using isotope::TopologyMode;
using isotope::Volume;
using isotope::bench::prepare;

// Minimum wall time of each timed benchmark. The heavy cases (257^3 at eps 0, preprocessing) run
// one or two iterations either way; the light ones still get hundreds. Kept short so the whole
// suite stays near a minute and a half on 2 cores; --benchmark_repetitions tightens estimates.
constexpr double kMinSeconds = 0.3;

// ---- Inputs, each built once per process ----------------------------------------------------

enum class Dataset { algebraic129, algebraic257, bolt };

const char* dataset_name(Dataset d) {
  switch (d) {
    case Dataset::algebraic129: return "algebraic129";
    case Dataset::algebraic257: return "algebraic257";
    case Dataset::bolt: return "bolt";
  }
  return "?";
}

// The isovalue each dataset is extracted at: the algebraic function's surface of the paper's
// Table 1, and the bolt's outer envelope (data/README.md: 20754 crossed cells).
float dataset_iso(Dataset d) { return d == Dataset::bolt ? 64.5f : 0.0f; }

// Coarse eps (data units) whose meshes have about 10% of the eps-0 triangles, measured: algebraic257
// 93424 of 938672 (9.95%), bolt 12694 of 133480 (9.5%; its plateaus keep the error bound high).
constexpr double kCoarseEpsAlgebraic = 0.0012;
constexpr double kCoarseEpsBolt = 330.0;
// Measured: at the eps above (and up to 0.5 and 700) preserve gives none's very triangles and
// simplify drops nothing whatever its delta (tets_simplified = 0), so the topology modes differ
// only at a very coarse eps, where preserve keeps more than the error alone would.
constexpr double kTopologyEpsAlgebraic = 2.0;
constexpr double kTopologyEpsBolt = 1500.0;

// Simplify mode's delta (interval weight |X|, data units): critical points whose isovalue interval
// is shorter may go. Measured (bench/README.md, "Simplify"): the critical points that matter at
// the topology eps above fall into two groups of weights, and each delta lies in the gap, so
// simplify drops the small group and keeps the other. algebraic257 at eps 2: weights in
// 1e-6..1e-4 and 0.2..0.3; preserve 136 triangles, simplify 100, none 60. bolt at eps 1500:
// weights in 40..48 and 128..256; preserve 1066, simplify 1030, none 370.
constexpr double kSimplifyDeltaAlgebraic = 0.05;
constexpr double kSimplifyDeltaBolt = 64.0;

double simplify_delta(Dataset d) { return d == Dataset::bolt ? kSimplifyDeltaBolt : kSimplifyDeltaAlgebraic; }

const Volume& bolt_volume() {
  static const Volume v = [] {
    const std::string path = std::string(ISOTOPE_TEST_DATA) + "/bolt_70x123x66_uint8.raw";
    const auto layout = isotope::parse_raw_name(path);
    if (!layout) throw std::runtime_error("cannot parse the layout of " + path);
    return isotope::read_raw(path, *layout);
  }();
  return v;
}

const Volume& volume_of(Dataset d) {
  switch (d) {
    case Dataset::algebraic129: {
      static const Volume v = isotope::generate_algebraic(129);
      return v;
    }
    case Dataset::algebraic257: {
      static const Volume v = isotope::generate_algebraic(257);
      return v;
    }
    case Dataset::bolt: return bolt_volume();
  }
  throw std::logic_error("unknown dataset");
}

const MultiresVolume& multires_of(Dataset d) {
  switch (d) {
    case Dataset::algebraic129: {
      static const MultiresVolume mv = MultiresVolume::build(volume_of(d));
      return mv;
    }
    case Dataset::algebraic257: {
      static const MultiresVolume mv = MultiresVolume::build(volume_of(d));
      return mv;
    }
    case Dataset::bolt: {
      static const MultiresVolume mv = MultiresVolume::build(volume_of(d));
      return mv;
    }
  }
  throw std::logic_error("unknown dataset");
}

// ---- Stores, each converted once per process -------------------------------------------------

const std::filesystem::path& store_dir() {
  static const isotope::TempDir dir(isotope::bench::process_temp_path("extract"));
  return dir.path();
}

// The dataset as a store (convert_to_store, default options: lossless, zstd level 3) in the
// process's temporary folder. The algebraic volume is written as float32 raw first, so that its
// store holds exactly BM_Extract's values.
const isotope::StoreReader& store_of(Dataset d) {
  const std::filesystem::path& dir = store_dir();  // constructed first, so destroyed after the readers
  static std::map<Dataset, std::unique_ptr<isotope::StoreReader>> stores;
  std::unique_ptr<isotope::StoreReader>& store = stores[d];
  if (store) return *store;
  std::string input;
  if (d == Dataset::bolt) {
    input = std::string(ISOTOPE_TEST_DATA) + "/bolt_70x123x66_uint8.raw";
  } else {
    const Volume& v = volume_of(d);
    input = (dir / (std::string(dataset_name(d)) + "_" + std::to_string(v.dims[0]) + "x" + std::to_string(v.dims[1]) +
                    "x" + std::to_string(v.dims[2]) + "_float32.raw"))
                .string();
    std::ofstream out(input, std::ios::binary);
    out.write(reinterpret_cast<const char*>(v.values.data()),
              static_cast<std::streamsize>(v.values.size() * sizeof(float)));
    if (!out) throw std::runtime_error("cannot write " + input);
  }
  const auto reader = isotope::open_box_reader({input, std::nullopt, std::nullopt}, dir.string());
  const std::string output = (dir / (std::string(dataset_name(d)) + ".isotope")).string();
  isotope::convert_to_store(*reader, output, isotope::ConvertOptions{});
  if (d != Dataset::bolt) std::filesystem::remove(input);
  store = std::make_unique<isotope::StoreReader>(output);
  return *store;
}

ExtractOptions paged_options(Dataset d, double eps) {
  ExtractOptions options;  // error bound, topology preserve: the CLI's defaults
  options.iso = dataset_iso(d);
  options.eps = eps;
  return options;
}

// Decoded bytes of every brick an extraction at EPS reaches: BrickCache::stats().peak_bytes of
// one run whose budget holds them all, measured once per (dataset, eps). The same whatever the
// thread count, since without eviction each brick is decoded once.
uint64_t decoded_bytes_of(Dataset d, double eps) {
  static std::map<std::pair<Dataset, double>, uint64_t> sizes;
  const auto found = sizes.find({d, eps});
  if (found != sizes.end()) return found->second;
  isotope::BrickCache cache(store_of(d), std::numeric_limits<uint64_t>::max());
  const isotope::PagedVolume volume(cache);
  const Mesh mesh = isotope::extract(volume, paged_options(d, eps));
  const uint64_t bytes = cache.stats().peak_bytes;
  sizes[{d, eps}] = bytes;
  return bytes;
}

void set_triangle_counters(benchmark::State& state, int64_t total_triangles) {
  const auto t = static_cast<double>(total_triangles);
  state.counters["triangles"] = benchmark::Counter(t, benchmark::Counter::kAvgIterations);
  state.counters["triangles_per_second"] = benchmark::Counter(t, benchmark::Counter::kIsRate);
}

// The data's voxels per wall-clock second, whatever the extraction touched: a coarse eps
// "processes" the same volume faster, which is the point of adaptivity.
void set_voxel_rate(benchmark::State& state, const std::array<int64_t, 3>& dims) {
  state.counters["voxels_per_second"] =
      benchmark::Counter(static_cast<double>(dims[0] * dims[1] * dims[2]) * static_cast<double>(state.iterations()),
                         benchmark::Counter::kIsRate);
}

// oneTBB capped at THREADS for as long as the result lives: the whole timed loop.
tbb::global_control thread_cap(int threads) {
  return tbb::global_control(tbb::global_control::max_allowed_parallelism, static_cast<size_t>(threads));
}

void set_thread_counter(benchmark::State& state) {
  state.counters["threads"] =
      static_cast<double>(tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism));
}

// ---- Benchmarks -------------------------------------------------------------------------------

// extract(): the adaptive traversal of the hierarchy, stopping rule, marching tetrahedra, welding.
// Simplify mode drops the critical points whose interval weight is under simplify_delta(d).
void BM_Extract(benchmark::State& state, Dataset d, double eps, TopologyMode mode, int threads) {
  const MultiresVolume* mv = nullptr;
  if (!prepare(state, [&] { mv = &multires_of(d); })) return;
  const tbb::global_control cap = thread_cap(threads);
  ExtractOptions options;
  options.iso = dataset_iso(d);
  options.eps = eps;
  options.error = isotope::ErrorIndicator::bound;
  options.topology = mode;
  if (mode == TopologyMode::simplify) {
    options.weight = isotope::SimplificationWeight::interval;
    options.delta = simplify_delta(d);
  }

  int64_t triangles = 0, tets_visited = 0, tets_simplified = 0;
  for (auto _ : state) {
    ExtractStats stats;
    Mesh mesh = isotope::extract(*mv, options, &stats);
    triangles += static_cast<int64_t>(mesh.triangles.size());
    tets_visited += stats.tets_visited;
    tets_simplified += stats.tets_simplified;
    benchmark::DoNotOptimize(mesh.triangles.data());
  }
  set_triangle_counters(state, triangles);
  set_voxel_rate(state, mv->data_dims());
  state.counters["tets_visited"] =
      benchmark::Counter(static_cast<double>(tets_visited), benchmark::Counter::kAvgIterations);
  if (mode == TopologyMode::simplify) {  // > 0: the mesh is not preserve's
    state.counters["tets_simplified"] =
        benchmark::Counter(static_cast<double>(tets_simplified), benchmark::Counter::kAvgIterations);
    state.counters["delta"] = options.delta;
  }
  set_thread_counter(state);
}

// extract() over a store: the same traversal, with values and records looked up in bricks read
// (pread), decompressed and decoded (band 0's records rebuilt) on demand through a BrickCache of
// a budget of: all the decoded bytes the extraction reaches (`full`: nothing evicted), an eighth of
// the whole store decoded (`eighth`: the target's "1/8 of the store"), or an eighth of what the
// extraction reaches (`eighth_reached`: stricter at coarse eps, which reaches few bricks).
// The cache is built inside the timed loop, so every iteration starts cold and pays for every
// read and decode; the store file itself stays in the OS page cache.
enum class PagedBudget { full, eighth, eighth_reached };

// A brick's core decoded (as a BrickCache holds it): every node's value and range-and-bound word in
// the bytes the store's type promises (held_value_bytes, held_bounds_bytes).
uint64_t store_decoded_bytes(const isotope::StoreReader& store) {
  const isotope::StoreLayout& l = store.layout();
  const int value_bytes = isotope::held_value_bytes(store.header());
  return static_cast<uint64_t>(l.brick_count()) *
         static_cast<uint64_t>(l.brick_nodes() * (value_bytes + isotope::held_bounds_bytes(value_bytes)));
}

void BM_ExtractPaged(benchmark::State& state, Dataset d, double eps, PagedBudget which, int threads) {
  const isotope::StoreReader* store = nullptr;
  uint64_t decoded = 0;
  if (!prepare(state, [&] {
        store = &store_of(d);
        decoded = decoded_bytes_of(d, eps);
      }))
    return;
  const tbb::global_control cap = thread_cap(threads);
  const ExtractOptions options = paged_options(d, eps);
  const uint64_t budget = which == PagedBudget::full     ? decoded
                          : which == PagedBudget::eighth ? store_decoded_bytes(*store) / 8
                                                         : decoded / 8;

  int64_t triangles = 0, bricks_read = 0;
  uint64_t bytes_read = 0;
  for (auto _ : state) {
    try {
      isotope::BrickCache cache(*store, budget);
      const isotope::PagedVolume volume(cache);
      Mesh mesh = isotope::extract(volume, options);
      benchmark::DoNotOptimize(mesh.triangles.data());
      triangles += static_cast<int64_t>(mesh.triangles.size());
      const isotope::BrickCacheStats s = cache.stats();
      bricks_read += s.bricks_read;
      bytes_read += s.bytes_read;
    } catch (const std::exception& e) {
      state.SkipWithError(e.what());
      break;
    }
  }
  set_triangle_counters(state, triangles);
  set_voxel_rate(state, store->header().dims);
  // Per iteration: compressed bytes and bricks read from the store (misses, re-reads included).
  state.counters["bricks_read"] =
      benchmark::Counter(static_cast<double>(bricks_read), benchmark::Counter::kAvgIterations);
  state.counters["bytes_read"] = benchmark::Counter(static_cast<double>(bytes_read), benchmark::Counter::kAvgIterations,
                                                    benchmark::Counter::OneK::kIs1024);
  state.counters["budget_MiB"] = static_cast<double>(budget) / (1 << 20);
  state.counters["decoded_MiB"] = static_cast<double>(decoded) / (1 << 20);
  state.counters["store_decoded_MiB"] = static_cast<double>(store_decoded_bytes(*store)) / (1 << 20);
  set_thread_counter(state);
}

// extract_full_resolution(): marching tetrahedra over every finest tetrahedron of the raw array,
// no hierarchy, no store; parallel over oneTBB, so it runs under the same cap as BM_Extract. Every
// extraction row is read as a ratio to the row of the same dataset and threads (bench/README.md,
// "JSON output and ratios against the baseline").
void BM_FullResolutionBaseline(benchmark::State& state, Dataset d, int threads) {
  const Volume* volume = nullptr;
  if (!prepare(state, [&] { volume = &volume_of(d); })) return;
  const tbb::global_control cap = thread_cap(threads);
  const float iso = dataset_iso(d);

  int64_t triangles = 0;
  for (auto _ : state) {
    Mesh mesh = isotope::extract_full_resolution(*volume, iso);
    triangles += static_cast<int64_t>(mesh.triangles.size());
    benchmark::DoNotOptimize(mesh.triangles.data());
  }
  set_triangle_counters(state, triangles);
  set_voxel_rate(state, volume->dims);
  set_thread_counter(state);
}

// measure_topology(): the summary line's counts (components, Euler characteristic, boundary and
// non-manifold edges) of algebraic 257^3's eps 0 mesh (939 k triangles), which every `isotope
// extract` without --quiet measures.
void BM_MeshTopology(benchmark::State& state, int threads) {
  const Mesh* mesh = nullptr;
  if (!prepare(state, [&] {
        static const Mesh full =
            isotope::extract_full_resolution(volume_of(Dataset::algebraic257), dataset_iso(Dataset::algebraic257));
        mesh = &full;
      }))
    return;
  const tbb::global_control cap = thread_cap(threads);
  int64_t triangles = 0;
  for (auto _ : state) {
    const isotope::MeshTopology t = isotope::measure_topology(*mesh);
    triangles += t.triangles;
    benchmark::DoNotOptimize(t.components);
  }
  set_triangle_counters(state, triangles);
  set_thread_counter(state);
}

// StoreReader::read_brick() of the core section, which is what a BrickCache miss runs
// (BrickCache::decode): pread, checksum, zstd decompression and field decoding. Not timed:
// the cache's bookkeeping, and band 0's records, computed when the traversal reads them. One
// iteration decodes every brick of the store once, in directory order, so the mix of bands is the
// store's own whatever the iteration count. The file stays in the OS page cache: CPU cost, not disk.
void BM_BrickDecode(benchmark::State& state, Dataset d) {
  const isotope::StoreReader* store = nullptr;
  if (!prepare(state, [&] { store = &store_of(d); })) return;
  const int64_t bricks = store->layout().brick_count();
  uint64_t compressed = 0;
  for (int64_t i = 0; i < bricks; ++i) compressed += store->entry(i).bytes[0];
  const uint64_t decoded = store_decoded_bytes(*store);
  std::vector<float> values(static_cast<size_t>(store->layout().brick_nodes()));
  std::vector<uint64_t> bounds(values.size());
  const isotope::BrickView view{values.data(), bounds.data(), nullptr, nullptr, nullptr, nullptr};

  for (auto _ : state) {
    try {
      for (int64_t i = 0; i < bricks; ++i) {
        store->read_brick(i, {true, false, false, false}, view, values.data());
        benchmark::DoNotOptimize(bounds.data());
      }
    } catch (const std::exception& e) {
      state.SkipWithError(e.what());
      break;
    }
  }
  const auto passes = static_cast<double>(state.iterations());
  state.SetBytesProcessed(static_cast<int64_t>(compressed) * state.iterations());  // bytes_per_second
  state.counters["decoded_bytes_per_second"] = benchmark::Counter(
      static_cast<double>(decoded) * passes, benchmark::Counter::kIsRate, benchmark::Counter::OneK::kIs1024);
  state.counters["bricks_per_second"] =
      benchmark::Counter(static_cast<double>(bricks) * passes, benchmark::Counter::kIsRate);
  state.counters["bricks"] = static_cast<double>(bricks);
  state.counters["compressed_MiB"] = static_cast<double>(compressed) / (1 << 20);
  state.counters["decoded_MiB"] = static_cast<double>(decoded) / (1 << 20);
}

// MultiresVolume::build(): embedding plus saturation of every per-vertex record, in parallel.
void BM_Preprocess(benchmark::State& state, Dataset d, int threads) {
  const Volume* volume = nullptr;
  if (!prepare(state, [&] { volume = &volume_of(d); })) return;
  const tbb::global_control cap = thread_cap(threads);

  int64_t lattice_nodes = 0;
  for (auto _ : state) {
    std::optional<MultiresVolume> mv = MultiresVolume::build(*volume);
    benchmark::DoNotOptimize(&*mv);
    state.PauseTiming();  // freeing the records is not part of preprocessing
    const int64_t side = mv->lattice().side;
    lattice_nodes = side * side * side;
    mv.reset();
    state.ResumeTiming();
  }
  state.counters["voxels_per_second"] = benchmark::Counter(
      static_cast<double>(volume->node_count()) * static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
  state.counters["lattice_nodes"] = static_cast<double>(lattice_nodes);
  set_thread_counter(state);
}

// Opening a band of a store checks that its directory's entries tile one run of the file
// (check_directory): 128^3 entries are a 2048^3 volume's band 0, checked
// once per process that reads it. Argument 0: the entries in the writer's Morton order (what every
// store holds, walked without a sort); 1: in a shuffled order (what the sort behind it costs).
void BM_StoreDirectoryCheck(benchmark::State& state) {
  const isotope::Box3 grid{128, 128, 128};
  const auto n = static_cast<size_t>(grid[0] * grid[1] * grid[2]);
  std::vector<isotope::BrickEntry> entries(n);
  std::vector<size_t> file_order;
  for (const isotope::Box3& b : isotope::in_morton_order(grid))
    file_order.push_back(static_cast<size_t>((b[2] * grid[1] + b[1]) * grid[0] + b[0]));
  std::mt19937_64 rng(7);
  if (state.range(0) == 1) std::shuffle(file_order.begin(), file_order.end(), rng);
  uint64_t at = isotope::kHeaderBytes;
  for (size_t i : file_order) {
    entries[i].offset = at;
    entries[i].bytes[0] = static_cast<uint32_t>(isotope::kChecksumBytes + 100 + rng() % 4000);
    at += entries[i].total();
  }
  isotope::BandDirectory d;
  d.checksum = isotope::store_checksum(entries.data(), n * sizeof(isotope::BrickEntry));
  for (auto _ : state) isotope::check_directory(entries, grid, d, at, "bench.isotope");
  state.counters["entries/s"] =
      benchmark::Counter(static_cast<double>(n), benchmark::Counter::kIsIterationInvariantRate);
}

// is_critical_pattern() over every pattern of the three polyhedron types (2^8 + 2^6 + 2^10).
void BM_CriticalTableLookup(benchmark::State& state) {
  constexpr isotope::PolyhedronType types[] = {isotope::PolyhedronType::cube, isotope::PolyhedronType::octahedron,
                                               isotope::PolyhedronType::diamond};
  int64_t patterns = 0;
  for (const auto type : types) patterns += int64_t{1} << (isotope::ring_size(type) + 2);
  benchmark::DoNotOptimize(isotope::is_critical_pattern(types[0], 0));  // builds the tables

  int64_t critical = 0;
  for (auto _ : state) {
    critical = 0;
    for (const auto type : types) {
      const uint32_t count = uint32_t{1} << (isotope::ring_size(type) + 2);
      for (uint32_t p = 0; p < count; ++p) {
        benchmark::DoNotOptimize(p);
        critical += isotope::is_critical_pattern(type, p) ? 1 : 0;
      }
    }
    benchmark::DoNotOptimize(critical);
  }
  state.SetItemsProcessed(state.iterations() * patterns);
  state.counters["critical"] = static_cast<double>(critical);  // 68 + 8 + 400 = 476
}

std::string format_eps(double eps) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%g", eps);
  return buffer;
}

std::string threads_suffix(int threads) { return "/threads:" + std::to_string(threads); }

// Registration in one table per benchmark, so that names read
// BM_Extract/<dataset>/eps:<eps>/mode:<mode>/threads:<n> and so on (bench/README.md).
void register_extract(const std::vector<int>& threads_list) {
  struct ExtractCase {
    Dataset dataset;
    std::vector<double> eps;  // in data units
  };
  // The second eps of each is the coarse one of BM_ExtractPaged (about 10% of the eps-0 triangles),
  // the last the one where the three topology modes differ.
  const ExtractCase cases[] = {
      {Dataset::algebraic257, {0.0, kCoarseEpsAlgebraic, 0.01, 0.1, kTopologyEpsAlgebraic}},
      {Dataset::bolt, {0.0, kCoarseEpsBolt, 8.0, 32.0, kTopologyEpsBolt}},
  };
  for (const auto& c : cases) {
    for (const double eps : c.eps)
      for (const TopologyMode mode : {TopologyMode::none, TopologyMode::preserve, TopologyMode::simplify})
        for (const int threads : threads_list) {
          const std::string name = std::string("BM_Extract/") + dataset_name(c.dataset) + "/eps:" + format_eps(eps) +
                                   "/mode:" + std::string(isotope::to_string(mode)) + threads_suffix(threads);
          benchmark::RegisterBenchmark(name.c_str(), BM_Extract, c.dataset, eps, mode, threads)
              ->Unit(benchmark::kMillisecond)
              ->UseRealTime()
              ->MinTime(kMinSeconds);
        }
    for (const int threads : threads_list)
      benchmark::RegisterBenchmark(
          (std::string("BM_FullResolutionBaseline/") + dataset_name(c.dataset) + threads_suffix(threads)).c_str(),
          BM_FullResolutionBaseline, c.dataset, threads)
          ->Unit(benchmark::kMillisecond)
          ->UseRealTime()
          ->MinTime(kMinSeconds);
  }
}

// BM_ExtractPaged/<dataset>/eps:<eps>/cache:<full|eighth|eighth_reached>/threads:<n>, then
// BM_BrickDecode/<dataset>: what each of the paged extraction's misses costs.
void register_paged(const std::vector<int>& threads_list) {
  const std::pair<Dataset, double> cases[] = {{Dataset::algebraic257, kCoarseEpsAlgebraic},
                                              {Dataset::bolt, kCoarseEpsBolt}};
  for (const auto& [d, coarse] : cases) {
    for (const double eps : {0.0, coarse})
      for (const PagedBudget which : {PagedBudget::full, PagedBudget::eighth, PagedBudget::eighth_reached})
        for (const int threads : threads_list) {
          const char* cache = which == PagedBudget::full     ? "/cache:full"
                              : which == PagedBudget::eighth ? "/cache:eighth"
                                                             : "/cache:eighth_reached";
          const std::string name = std::string("BM_ExtractPaged/") + dataset_name(d) + "/eps:" + format_eps(eps) +
                                   cache + threads_suffix(threads);
          benchmark::RegisterBenchmark(name.c_str(), BM_ExtractPaged, d, eps, which, threads)
              ->Unit(benchmark::kMillisecond)
              ->UseRealTime()
              ->MinTime(kMinSeconds);
        }
  }
  for (const auto& c : cases)
    benchmark::RegisterBenchmark((std::string("BM_BrickDecode/") + dataset_name(c.first)).c_str(), BM_BrickDecode,
                                 c.first)
        ->Unit(benchmark::kMillisecond)
        ->UseRealTime()
        ->MinTime(kMinSeconds);
}

void register_benchmarks() {
  const std::vector<int> threads_list = isotope::bench::thread_counts();
  register_extract(threads_list);
  register_paged(threads_list);
  for (const Dataset d : {Dataset::algebraic129, Dataset::algebraic257, Dataset::bolt})
    for (const int threads : threads_list)
      benchmark::RegisterBenchmark((std::string("BM_Preprocess/") + dataset_name(d) + threads_suffix(threads)).c_str(),
                                   BM_Preprocess, d, threads)
          ->Unit(benchmark::kMillisecond)
          ->UseRealTime()
          ->MinTime(kMinSeconds);
  for (const int threads : threads_list)
    benchmark::RegisterBenchmark(
        (std::string("BM_MeshTopology/") + dataset_name(Dataset::algebraic257) + threads_suffix(threads)).c_str(),
        BM_MeshTopology, threads)
        ->Unit(benchmark::kMillisecond)
        ->UseRealTime()
        ->MinTime(kMinSeconds);
  benchmark::RegisterBenchmark("BM_CriticalTableLookup", BM_CriticalTableLookup)->Unit(benchmark::kMicrosecond);
  benchmark::RegisterBenchmark("BM_StoreDirectoryCheck", BM_StoreDirectoryCheck)
      ->ArgName("shuffled")
      ->Arg(0)
      ->Arg(1)
      ->Unit(benchmark::kMillisecond);
}

}  // namespace

int main(int argc, char** argv) {
  register_benchmarks();
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
