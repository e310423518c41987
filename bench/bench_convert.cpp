// Google Benchmark pair: `convert_to_store` throughput, next to its ceiling measured in the same
// run (reading the same bytes through the same BoxReader in the converter's band-0 tiles and
// zstd-compressing them at the same level). Target: convert >= 50% of the ceiling, all threads.
// How to run and read them: bench/README.md, "Convert throughput against its ceiling".
//
// Inputs are written once per process into a temporary folder, removed at exit. Times are
// wall-clock (UseRealTime): the work runs on oneTBB's workers.
#include <benchmark/benchmark.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>
#include <unistd.h>
#include <zstd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <exception>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <system_error>
#include <thread>
#include <vector>

#include "bench/bench_support.h"
#include "engine/hierarchy/store_layout.h"
#include "engine/synthetic/fields.h"
#include "io/store/store_writer.h"
#include "io/volume/box_reader.h"
#include "io/volume/raw_reader.h"
#include "isotope/volume.h"

namespace {

namespace fs = std::filesystem;
using isotope::Box3;
using isotope::bench::prepare;

constexpr int kZstdLevel = 3;  // ConvertOptions' default, used by both benchmarks of the pair
constexpr double kMB = 1e6;

// ---- Inputs, each written and opened once per process ----------------------------------------

// A per-process temporary folder, removed (with everything left in it) at exit.
const fs::path& temp_dir() {
  struct TempDir {
    fs::path path;
    TempDir() : path(fs::temp_directory_path() / ("isotope_bench_convert." + std::to_string(::getpid()))) {
      fs::create_directories(path);
    }
    ~TempDir() {
      std::error_code ignored;
      fs::remove_all(path, ignored);
    }
  };
  static const TempDir dir;
  return dir.path;
}

enum class Input { noise257, bolt };

const char* input_name(Input d) { return d == Input::noise257 ? "noise257_uint16" : "bolt"; }

// generate_noise(257) (smooth, in [-1, 1]) scaled to 0 .. 65535, written as uint16 raw.
std::string write_noise257() {
  const fs::path path = temp_dir() / "noise_257x257x257_uint16.raw";
  std::vector<uint16_t> data;
  {
    const isotope::Volume v = isotope::generate_noise(257, 1);
    data.resize(v.values.size());
    for (size_t i = 0; i < data.size(); ++i)
      data[i] = static_cast<uint16_t>(std::lround(std::clamp((v.values[i] + 1.0) * 0.5, 0.0, 1.0) * 65535.0));
  }
  std::ofstream out(path, std::ios::binary);
  out.write(reinterpret_cast<const char*>(data.data()), static_cast<std::streamsize>(data.size() * sizeof(uint16_t)));
  if (!out) throw std::runtime_error("cannot write " + path.string());
  return path.string();
}

const isotope::BoxReader& reader_of(Input d) {
  switch (d) {
    case Input::noise257: {
      static const auto r = isotope::open_box_reader({write_noise257(), std::nullopt, std::nullopt}, temp_dir());
      return *r;
    }
    case Input::bolt: {
      static const auto r = isotope::open_box_reader(
          {std::string(ISOTOPE_TEST_DATA) + "/bolt_70x123x66_uint8.raw", std::nullopt, std::nullopt}, temp_dir());
      return *r;
    }
  }
  throw std::logic_error("unknown input");
}

// THREADS = 1 or the machine's core count, held for the whole timed loop.
tbb::global_control thread_cap(int threads) {
  return tbb::global_control(tbb::global_control::max_allowed_parallelism, static_cast<size_t>(threads));
}

uint64_t input_bytes_of(const isotope::VolumeInfo& info) {
  return static_cast<uint64_t>(info.dims[0] * info.dims[1] * info.dims[2]) * static_cast<uint64_t>(info.element_bytes);
}

// The counters both benchmarks of the pair report, over wall-clock time.
void set_rate_counters(benchmark::State& state, const isotope::VolumeInfo& info, double output_bytes) {
  const uint64_t input = input_bytes_of(info);
  const auto iterations = static_cast<double>(state.iterations());
  state.SetBytesProcessed(static_cast<int64_t>(input) * state.iterations());
  state.counters["MB_per_second"] =
      benchmark::Counter(static_cast<double>(input) / kMB * iterations, benchmark::Counter::kIsRate);
  state.counters["voxels_per_second"] = benchmark::Counter(
      static_cast<double>(info.dims[0] * info.dims[1] * info.dims[2]) * iterations, benchmark::Counter::kIsRate);
  state.counters["size_ratio"] = output_bytes / static_cast<double>(input);
  state.counters["threads"] =
      static_cast<double>(tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism));
}

// ---- Ceiling: read + compress the same bytes in the same tiles ---------------------------------

// The core's values narrowed back to the input's element type, its bytes appended to OUT: the
// bytes of the input file, which is what the target's ceiling compresses. (The converter's field
// codec also turns integer-valued data into narrow deltas before zstd, so it compresses about
// this many bytes, not 4 per value.)
template <class T>
void append_as(const std::vector<float>& values, std::vector<uint8_t>& out) {
  const size_t at = out.size();
  out.resize(at + values.size() * sizeof(T));
  for (size_t i = 0; i < values.size(); ++i) {
    const T v = static_cast<T>(values[i]);
    std::memcpy(out.data() + at + i * sizeof(T), &v, sizeof(T));
  }
}

void append_element_bytes(isotope::ScalarType type, const std::vector<float>& values, std::vector<uint8_t>& out) {
  switch (type) {
    case isotope::ScalarType::uint8: return append_as<uint8_t>(values, out);
    case isotope::ScalarType::uint16: return append_as<uint16_t>(values, out);
    case isotope::ScalarType::int16: return append_as<int16_t>(values, out);
    case isotope::ScalarType::float32: return append_as<float>(values, out);
    case isotope::ScalarType::float64: return append_as<double>(values, out);
  }
}

constexpr int64_t kBrickWidth = int64_t{1} << isotope::kDefaultBrickBits;  // 16

// One band-0 tile as the converter reads it: C^3 bricks of 16^3 plus a halo of two nodes, clipped
// to the volume, in one read_box. Each brick's core is narrowed to the element type and compressed
// on its own, as the store compresses bricks; returns the compressed bytes of the tile.
size_t read_and_compress_tile(const isotope::BoxReader& reader, isotope::ScalarType type, int64_t c, const Box3& tile) {
  const auto& dims = reader.info().dims;
  const int64_t t = kBrickWidth;
  Box3 lo{}, size{}, core_hi{};
  for (int a = 0; a < 3; ++a) {
    const int64_t c0 = tile[a] * c * t;
    core_hi[a] = std::min(c0 + c * t, dims[a]);
    lo[a] = std::max<int64_t>(c0 - 2, 0);
    size[a] = std::min(core_hi[a] + 2, dims[a]) - lo[a];
  }
  std::vector<float> box(static_cast<size_t>(size[0] * size[1] * size[2]));
  reader.read_box(lo, size, box.data());

  size_t compressed_bytes = 0;
  std::vector<float> core;
  std::vector<uint8_t> raw, compressed;
  for (int64_t bz = tile[2] * c * t; bz < core_hi[2]; bz += t)
    for (int64_t by = tile[1] * c * t; by < core_hi[1]; by += t)
      for (int64_t bx = tile[0] * c * t; bx < core_hi[0]; bx += t) {
        core.clear();
        for (int64_t z = bz; z < std::min(bz + t, core_hi[2]); ++z)
          for (int64_t y = by; y < std::min(by + t, core_hi[1]); ++y) {
            const float* row = box.data() + ((z - lo[2]) * size[1] + (y - lo[1])) * size[0] + (bx - lo[0]);
            core.insert(core.end(), row, row + (std::min(bx + t, core_hi[0]) - bx));
          }
        raw.clear();
        append_element_bytes(type, core, raw);
        compressed.resize(ZSTD_compressBound(raw.size()));
        const size_t n = ZSTD_compress(compressed.data(), compressed.size(), raw.data(), raw.size(), kZstdLevel);
        if (ZSTD_isError(n)) throw std::runtime_error(std::string("zstd: ") + ZSTD_getErrorName(n));
        compressed_bytes += n;
      }
  return compressed_bytes;
}

// ---- Benchmarks -------------------------------------------------------------------------------

// convert_to_store(): the whole store (every band) written to a temporary file, removed untimed.
void BM_Convert(benchmark::State& state, Input d, int threads) {
  const isotope::BoxReader* reader = nullptr;
  if (!prepare(state, [&] { reader = &reader_of(d); })) return;
  const tbb::global_control cap = thread_cap(threads);
  isotope::ConvertOptions options;
  options.zstd_level = kZstdLevel;
  const std::string output = (temp_dir() / "convert.store").string();

  double output_bytes = 0;
  for (auto _ : state) {
    try {
      output_bytes = static_cast<double>(isotope::convert_to_store(*reader, output, options).output_bytes);
    } catch (const std::exception& e) {
      state.SkipWithError(e.what());
      break;
    }
    state.PauseTiming();
    fs::remove(output);
    state.ResumeTiming();
  }
  set_rate_counters(state, reader->info(), output_bytes);
}

// The ceiling: every band-0 tile of TILE_BRICKS^3 bricks read through the same reader and each
// brick's core compressed at the same level, in parallel over tiles under the same thread cap.
// Nothing is written. TILE_BRICKS = 1 is one 16^3 brick per tile: 20^3 boxes stepping by 16.
void BM_ConvertCeiling(benchmark::State& state, Input d, int64_t tile_bricks, int threads) {
  const isotope::BoxReader* reader = nullptr;
  std::optional<isotope::ScalarType> type;
  if (!prepare(state, [&] {
        reader = &reader_of(d);
        type = isotope::parse_scalar_type(reader->info().type);
        if (!type) throw std::runtime_error("unsupported element type " + reader->info().type);
      }))
    return;
  const tbb::global_control cap = thread_cap(threads);
  const auto& dims = reader->info().dims;
  const int64_t w = tile_bricks * kBrickWidth;  // tile width in nodes
  const Box3 grid{(dims[0] + w - 1) / w, (dims[1] + w - 1) / w, (dims[2] + w - 1) / w};
  const int64_t tiles = grid[0] * grid[1] * grid[2];

  double output_bytes = 0;
  for (auto _ : state) {
    std::atomic<uint64_t> compressed{0};
    try {
      tbb::parallel_for(int64_t{0}, tiles, [&](int64_t i) {
        const Box3 tile{i % grid[0], i / grid[0] % grid[1], i / (grid[0] * grid[1])};
        compressed += read_and_compress_tile(*reader, *type, tile_bricks, tile);
      });
    } catch (const std::exception& e) {
      state.SkipWithError(e.what());
      break;
    }
    output_bytes = static_cast<double>(compressed.load());
  }
  set_rate_counters(state, reader->info(), output_bytes);
}

// Names read BM_Convert/<input>/threads:<1|all> and BM_ConvertCeiling/<input>/tile:<32|128>/
// threads:<1|all>, each convert next to its ceilings. tile:32 reads a 36^3 box per 32^3 brick;
// tile:128 reads 4^3 bricks at once (132^3), as the converter does with its default memory budget.
void register_benchmarks() {
  const int all = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  for (const Input d : {Input::noise257, Input::bolt}) {
    for (const int threads : {1, all}) {
      const std::string threads_name = threads == 1 ? "/threads:1" : "/threads:all";
      benchmark::RegisterBenchmark(("BM_Convert/" + std::string(input_name(d)) + threads_name).c_str(), BM_Convert, d,
                                   threads)
          ->Unit(benchmark::kMillisecond)
          ->UseRealTime()
          ->MinTime(0.5);
      for (const int64_t tile_bricks : {1, 4}) {
        const std::string name = "BM_ConvertCeiling/" + std::string(input_name(d)) +
                                 "/tile:" + std::to_string(tile_bricks * kBrickWidth) + threads_name;
        benchmark::RegisterBenchmark(name.c_str(), BM_ConvertCeiling, d, tile_bricks, threads)
            ->Unit(benchmark::kMillisecond)
            ->UseRealTime()
            ->MinTime(0.5);
      }
    }
  }
}

// Registered before main() runs (the extraction benchmarks own main), from a static initializer.
[[maybe_unused]] const bool registered = (register_benchmarks(), true);

}  // namespace
