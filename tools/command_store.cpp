// isotope convert | info | verify: making, describing and checking stores (docs/FORMAT.md).
#include <oneapi/tbb/global_control.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <array>
#include <atomic>
#include <cstdio>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>

#include "engine/extract/traversal.h"
#include "io/file/atomic_file.h"
#include "io/store/brick_cache.h"
#include "io/store/paged_volume.h"
#include "io/store/store_reader.h"
#include "io/store/store_writer.h"
#include "io/volume/box_reader.h"
#include "io/volume/raw_reader.h"
#include "isotope/error.h"
#include "isotope/source.h"
#include "tools/commands.h"
#include "tools/support/interrupt_guard.h"

namespace isotope::tools {
namespace {

struct ConvertArgs {
  std::string input, output, dims, type;
  int64_t memory_mb = ConvertOptions{}.memory_mb;
  int threads = 0;
  int zstd_level = ConvertOptions{}.zstd_level;
  int quantize = 0;
  int brick_bits = kDefaultBrickBits;
  bool quiet = false;
};

int run_convert(const ConvertArgs& a) {
  // Every tile allocates and frees buffers of the same few sizes; glibc would hand the large
  // ones back to the kernel at once and fault fresh zeroed pages in for the next tile. Kept
  // instead, they are reused: the peak stays what it was, the page faults go.
  keep_freed_memory();
  std::optional<tbb::global_control> threads;
  if (a.threads > 0) threads.emplace(tbb::global_control::max_allowed_parallelism, static_cast<size_t>(a.threads));
  VolumeSpec input;
  input.path = a.input;
  if (!a.dims.empty()) input.dims = parse_dims(a.dims);
  if (!a.type.empty()) input.type = parse_scalar_type(a.type);

  ConvertOptions options;
  options.memory_mb = a.memory_mb;
  options.zstd_level = a.zstd_level;
  options.quantize_bits = a.quantize;
  options.brick_bits = a.brick_bits;
  RunContext run;
  run.distribution = process_group();  // under mpirun: the ranks share the tiles (docs/DISTRIBUTED.md)
  if (progress_enabled(a.quiet)) run.progress = progress_bar("converting");
  // Alone: Ctrl-C stops the convert between tiles, and its temporary output is removed as it
  // unwinds. Under mpirun the signal ends the rank at once instead (the command's main).
  std::optional<InterruptGuard> guard;
  if (!process_group()) {
    guard.emplace();
    run.cancel = &InterruptGuard::flag();
  }
  const ConvertStats s = convert(input, a.output, options, run);
  if (!a.quiet && speaking_rank()) {
    const auto& d = s.dims;
    std::printf(
        "%s: %lldx%lldx%lld %s, %lld bricks, %.1f MB (%.3fx the input's %.1f MB); %.2f s, %.1f MB/s\n",
        a.output.c_str(), static_cast<long long>(d[0]), static_cast<long long>(d[1]), static_cast<long long>(d[2]),
        s.type.c_str(), static_cast<long long>(s.bricks), static_cast<double>(s.output_bytes) / 1e6,
        static_cast<double>(s.output_bytes) / static_cast<double>(s.input_bytes),
        static_cast<double>(s.input_bytes) / 1e6, s.seconds, static_cast<double>(s.input_bytes) / 1e6 / s.seconds);
  }
  return 0;
}

nlohmann::ordered_json info_json(const StoreReader& store) {
  const StoreHeader& h = store.header();
  const StoreLayout& layout = store.layout();
  nlohmann::ordered_json j;
  j["file"] = store.path();
  j["format_version"] = kStoreVersion;
  j["dims"] = h.dims;
  j["type"] = h.source_type;
  j["spacing"] = h.spacing;
  j["origin"] = h.origin;
  j["lattice_side"] = layout.lattice().side;
  j["levels"] = layout.lattice().max_level() + 1;
  j["bands"] = layout.bands().size();
  j["brick_nodes"] = layout.brick_width();
  j["bricks"] = h.brick_count;
  j["file_bytes"] = store.file_bytes();
  j["input_bytes"] = h.input_bytes;
  j["size_ratio"] = static_cast<double>(store.file_bytes()) / static_cast<double>(h.input_bytes);
  j["zstd_level"] = h.zstd_level;
  j["value_range"] = {h.value_min, h.value_max};
  j["quantize_bits"] = h.quantize_bits;
  if (h.quantize_bits != 0) j["quantization_step"] = h.value_scale;
  j["critical_paper"] = {
      {"cube", h.critical_paper[0]}, {"octahedron", h.critical_paper[1]}, {"diamond", h.critical_paper[2]}};
  j["critical_exact"] = {
      {"cube", h.critical_exact[0]}, {"octahedron", h.critical_exact[1]}, {"diamond", h.critical_exact[2]}};
  // The largest simplification weights, in data units: a delta above one drops every critical
  // point (the none mesh), so they bound what --delta is worth trying. The record of the roots'
  // refinement vertex, the lattice's centre, is saturated over every vertex below it: all of them.
  std::array<float, 3> weights{0, 0, 0};
  if (layout.lattice().k >= 1) {
    BrickCache cache(store, 0);
    const PagedVolume volume(cache);
    PagedVolume::Reader reader = volume.reader();
    const int64_t c = layout.lattice().n / 2;
    weights =
        reader.topology(reader.locate(traversal::pack({c, c, c})), RecordFields{false, false, true, false}).weight;
  }
  const double code = h.quantize_bits != 0 ? h.value_scale : 1.0;
  j["largest_weights"] = {
      {"interval", weights[0] * code}, {"gradient", weights[1] * code * code}, {"size", weights[2]}};
  // Where the bytes are: per band, and per section (docs/FORMAT.md): what each mode reads.
  nlohmann::ordered_json bands = nlohmann::ordered_json::array();
  std::array<uint64_t, kSections> sections{};
  for (const Band& b : layout.bands()) {
    std::array<uint64_t, kSections> mine{};
    for (int64_t i = b.first_brick; i < b.first_brick + b.brick_count(); ++i)
      for (int k = 0; k < kSections; ++k) mine[static_cast<size_t>(k)] += store.entry(i).bytes[static_cast<size_t>(k)];
    uint64_t bytes = 0;
    for (int k = 0; k < kSections; ++k)
      bytes += mine[static_cast<size_t>(k)], sections[static_cast<size_t>(k)] += mine[static_cast<size_t>(k)];
    bands.push_back({{"scale", b.scale}, {"nodes", b.nodes}, {"bricks", b.brick_count()}, {"bytes", bytes}});
  }
  j["section_bytes"] = {
      {"core", sections[0]}, {"exact", sections[1]}, {"weights", sections[2]}, {"extra", sections[3]}};
  j["band_detail"] = bands;
  return j;
}

void print_info(const nlohmann::ordered_json& j) {
  auto dims = [](const nlohmann::ordered_json& d) {
    return std::to_string(d[0].get<int64_t>()) + "x" + std::to_string(d[1].get<int64_t>()) + "x" +
           std::to_string(d[2].get<int64_t>());
  };
  std::printf("store        %s (format version %d)\n", j["file"].get<std::string>().c_str(),
              j["format_version"].get<int>());
  std::printf("volume       %s %s, spacing %g %g %g\n", dims(j["dims"]).c_str(), j["type"].get<std::string>().c_str(),
              j["spacing"][0].get<double>(), j["spacing"][1].get<double>(), j["spacing"][2].get<double>());
  std::printf("hierarchy    lattice %lld^3, %d levels, %zu bands\n", j["lattice_side"].get<long long>(),
              j["levels"].get<int>(), j["bands"].get<size_t>());
  std::printf("bricks       %lld of %lld^3 nodes\n", j["bricks"].get<long long>(), j["brick_nodes"].get<long long>());
  std::printf("size         %.2f MB, %.3fx the input (%.2f MB); zstd level %d\n", j["file_bytes"].get<double>() / 1e6,
              j["size_ratio"].get<double>(), j["input_bytes"].get<double>() / 1e6, j["zstd_level"].get<int>());
  const auto& sb = j["section_bytes"];
  std::printf(
      "sections     core %.2f MB, exact intervals %.2f MB, weights %.2f MB, paper intervals and surplus %.2f MB\n",
      sb["core"].get<double>() / 1e6, sb["exact"].get<double>() / 1e6, sb["weights"].get<double>() / 1e6,
      sb["extra"].get<double>() / 1e6);
  std::printf("values       %g .. %g", j["value_range"][0].get<double>(), j["value_range"][1].get<double>());
  if (j["quantize_bits"].get<int>() != 0)
    std::printf(", quantized to %d bits (step %g)", j["quantize_bits"].get<int>(),
                j["quantization_step"].get<double>());
  else
    std::printf(", lossless");
  std::printf("\n");
  for (const char* rule : {"critical_paper", "critical_exact"})
    std::printf("%-12s cube %lld, octahedron %lld, diamond %lld\n", rule, j[rule]["cube"].get<long long>(),
                j[rule]["octahedron"].get<long long>(), j[rule]["diamond"].get<long long>());
  const auto& w = j["largest_weights"];
  std::printf("weights      largest interval %g, gradient %g, size %g (simplify: --delta above drops all)\n",
              w["interval"].get<double>(), w["gradient"].get<double>(), w["size"].get<double>());
}

}  // namespace

Command add_convert_command(CLI::App& app) {
  auto a = std::make_shared<ConvertArgs>();
  CLI::App* cmd =
      app.add_subcommand("convert", "Convert a volume into a store for out-of-core extraction (bounded memory)");
  cmd->add_option("INPUT", a->input,
                  "Volume: NAME_XxYxZ_TYPE.raw, any .raw with --dims/--type, FILE.h5:/path/to/dataset, or .nrrd/.nhdr")
      ->required();
  cmd->add_option("OUTPUT", a->output, "Store to write (e.g. volume.isotope)")->required();
  cmd->add_option("--memory-mb", a->memory_mb,
                  "Memory budget in MB: tiles in flight and level-to-level scratch; what does not fit goes to "
                  "unlinked scratch files beside the output")
      ->check(CLI::Range(int64_t{1}, int64_t{1} << 30))
      ->capture_default_str();
  cmd->add_option("--threads", a->threads, "Worker threads (0 = all cores)")
      ->check(thread_count_check())
      ->capture_default_str();
  cmd->add_option("--zstd-level", a->zstd_level, "zstd compression level of the bricks (1..19)")
      ->check(CLI::Range(1, 19))
      ->capture_default_str();
  cmd->add_option("--quantize", a->quantize,
                  "Float input: store values as 8- or 16-bit codes over the data range; half a code step is "
                  "added to the error indicators (default: lossless)")
      ->check(CLI::IsMember({8, 16}))
      ->type_name("BITS");
  cmd->add_option("--brick-bits", a->brick_bits,
                  "Bricks of 2^B nodes per axis: smaller bricks read less around a coarse surface, larger ones make "
                  "a smaller directory")
      ->check(CLI::Range(kMinBrickBits, kMaxBrickBits))
      ->capture_default_str()
      ->type_name("B");
  cmd->add_option("--dims", a->dims, "Raw input: nodes per axis, e.g. 301x324x56 (overrides the file name)")
      ->type_name("XxYxZ");
  cmd->add_option("--type", a->type, "Raw input: value type (overrides the file name)")
      ->check(CLI::IsMember({"uint8", "uint16", "int16", "float32", "float64"}));
  cmd->add_flag("-q,--quiet", a->quiet, "Print nothing on success");
  return [a] {
    if (!a->dims.empty() && !parse_dims(a->dims))
      throw CLI::ValidationError("--dims", "must look like 64x64x32, got '" + a->dims + "'");
    return run_convert(*a);
  };
}

Command add_info_command(CLI::App& app) {
  auto path = std::make_shared<std::string>();
  auto json = std::make_shared<bool>(false);
  CLI::App* cmd = app.add_subcommand("info", "Describe a store: dimensions, levels, bricks, sizes, critical points");
  cmd->add_option("STORE", *path, "Store file")->required();
  cmd->add_flag("--json", *json, "Print JSON instead of text");
  return [path, json] {
    const StoreReader store(*path);
    const nlohmann::ordered_json j = info_json(store);
    if (*json)
      std::cout << j.dump(2) << std::endl;
    else
      print_info(j);
    return 0;
  };
}

Command add_verify_command(CLI::App& app) {
  auto path = std::make_shared<std::string>();
  auto quiet = std::make_shared<bool>(false);
  auto threads = std::make_shared<int>(0);
  CLI::App* cmd = app.add_subcommand("verify", "Read every brick of a store and check checksums and invariants");
  cmd->add_option("STORE", *path, "Store file")->required();
  cmd->add_option("--threads", *threads, "Worker threads (0 = all cores)")->check(thread_count_check());
  cmd->add_flag("-q,--quiet", *quiet, "Print nothing on success");
  return [path, quiet, threads] {
    std::optional<tbb::global_control> limit;
    if (*threads > 0) limit.emplace(tbb::global_control::max_allowed_parallelism, static_cast<size_t>(*threads));
    const VerifyStats s =
        verify_store(*path, progress_enabled(*quiet) ? progress_bar("verifying") : ProgressCallback{});
    if (!*quiet)
      std::printf("%s: ok, %lld bricks, %.2f MB\n", path->c_str(), static_cast<long long>(s.bricks),
                  static_cast<double>(s.compressed_bytes) / 1e6);
    return 0;
  };
}

}  // namespace isotope::tools
