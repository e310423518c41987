#include "io/store/store_writer.h"

#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "engine/core/parallel.h"
#include "engine/core/volume_check.h"
#include "engine/hierarchy/band_tile.h"
#include "engine/hierarchy/banded_build.h"
#include "engine/hierarchy/compact_record.h"
#include "io/file/atomic_file.h"
#include "io/file/scratch_file.h"
#include "io/store/store_format.h"
#include "io/volume/volume_box_reader.h"
#include "isotope/error.h"

namespace isotope {

static_assert(kDefaultBrickBits == StoreLayout::kDefaultBrickBits,
              "isotope/convert.h names the store layout's default");
namespace {

// A band's hand-over (engine/hierarchy/banded_build.h) in two unlinked scratch files beside the output, for
// volumes whose hand-over does not fit the budget.
class ScratchHandover : public BandHandover {
 public:
  ScratchHandover(const std::string& dir, const Box3& nodes) : BandHandover(nodes), values_(dir), children_(dir) {}
  void write_row(int64_t x0, int64_t y, int64_t z, const float* v, const Record* r, int64_t n) override {
    values_.write(v, static_cast<size_t>(n) * sizeof(float), at(x0, y, z) * sizeof(float));
    children_.write(r, static_cast<size_t>(n) * sizeof(Record), at(x0, y, z) * sizeof(Record));
  }
  void read_values(int64_t x0, int64_t count, int64_t y, int64_t z, float* out) const override {
    values_.read(out, static_cast<size_t>(count) * sizeof(float), at(x0, y, z) * sizeof(float));
  }
  void read_children(int64_t x0, int64_t count, int64_t y, int64_t z, Record* out) const override {
    children_.read(out, static_cast<size_t>(count) * sizeof(Record), at(x0, y, z) * sizeof(Record));
  }

 private:
  ScratchFile values_, children_;
};

// The input as integer codes 0 .. 2^bits - 1 over [offset, offset + scale * (2^bits - 1)].
class QuantizingReader : public BoxReader {
 public:
  QuantizingReader(const BoxReader& input, int bits, const std::atomic<bool>* cancel) : input_(input) {
    info_ = input.info();
    const auto [lo, hi] = value_range(cancel);
    offset_ = lo;
    max_ = hi;
    scale_ = hi > lo ? (hi - lo) / static_cast<double>((1 << bits) - 1) : 1.0;
    max_code_ = static_cast<float>((1 << bits) - 1);
  }
  double offset() const { return offset_; }
  double max() const { return max_; }
  double scale() const { return scale_; }
  void read_box(const Box3& lo, const Box3& size, float* out) const override {
    input_.read_box(lo, size, out);
    const int64_t n = size[0] * size[1] * size[2];
    for (int64_t i = 0; i < n; ++i)
      out[i] = std::clamp(std::nearbyint(static_cast<float>((out[i] - offset_) / scale_)), 0.0f, max_code_);
  }

 private:
  // One streaming pass, a few rows at a time.
  std::pair<double, double> value_range(const std::atomic<bool>* cancel) const {
    const Box3& d = info_.dims;
    const int64_t rows = std::clamp<int64_t>((int64_t{1} << 20) / d[0], 1, d[1]);
    std::vector<float> buf(static_cast<size_t>(d[0] * rows));
    double lo = INFINITY, hi = -INFINITY;
    for (int64_t z = 0; z < d[2]; ++z) {
      if (cancel && cancel->load()) throw IoError("interrupted");
      for (int64_t y = 0; y < d[1]; y += rows) {
        const Box3 size{d[0], std::min(rows, d[1] - y), 1};
        input_.read_box({0, y, z}, size, buf.data());
        const auto [mn, mx] = std::minmax_element(buf.begin(), buf.begin() + size[0] * size[1]);
        lo = std::min(lo, static_cast<double>(*mn));
        hi = std::max(hi, static_cast<double>(*mx));
      }
    }
    return {lo, hi};
  }

  const BoxReader& input_;
  double offset_ = 0, max_ = 0, scale_ = 1;
  float max_code_ = 255;
};

// The fields of the brick whose first node is `origin` (G_j units) of a built tile, as the store
// holds them: values, and for bands that store records each field rounded as the compact record
// (engine/hierarchy/compact_record.h). Band 0 and the corners: values only.
BrickFields brick_fields(const BandTile& tile, const Box3& origin) {
  const StoreLayout& layout = tile.layout();
  const int j = tile.band();
  const Band& band = layout.band(j);
  const int64_t t = layout.brick_width();
  const auto nodes = static_cast<uint32_t>(layout.brick_nodes());
  BrickFields f;
  f.values.assign(nodes, 0.0f);  // nodes beyond the band's grid: 0
  // Walked row by row of the tile's window (x fastest), written at each node's Morton position.
  const Box3 end{std::min(t, band.nodes[0] - origin[0]), std::min(t, band.nodes[1] - origin[1]),
                 std::min(t, band.nodes[2] - origin[2])};
  for (int64_t z = 0; z < end[2]; ++z)
    for (int64_t y = 0; y < end[1]; ++y) {
      const uint32_t yz = spread_bits_3(y) << 1 | spread_bits_3(z) << 2;
      for (int64_t x = 0; x < end[0]; ++x)
        f.values[yz | spread_bits_3(x)] = tile.node_value({origin[0] + x, origin[1] + y, origin[2] + z});
    }
  if (!stores_records(layout, j)) return f;
  for (auto& r : f.records) r.reserve(nodes - nodes / 8);
  for (uint32_t m = 0; m < nodes; ++m) {
    if ((m & 7) == 0) continue;
    const Box3 g{origin[0] + compact_bits_3(m), origin[1] + compact_bits_3(m >> 1), origin[2] + compact_bits_3(m >> 2)};
    if (!(g[0] < band.nodes[0] && g[1] < band.nodes[1] && g[2] < band.nodes[2])) {
      for (auto& r : f.records) r.push_back(0.0f);
      continue;
    }
    const Record& r = tile.node_record(g);
    const PackedBounds b = pack_bounds(r.bounds);
    const PackedTopology p = pack_topology(r.topology, r.bounds.error_surplus);
    f.records[BrickFields::lo].push_back(bf16_to_float(b.lo));
    f.records[BrickFields::hi].push_back(bf16_to_float(b.hi));
    f.records[BrickFields::bound].push_back(b.bound);
    f.records[BrickFields::exact_lo].push_back(bf16_to_float(p.exact_lo));
    f.records[BrickFields::exact_hi].push_back(bf16_to_float(p.exact_hi));
    for (int w = 0; w < 3; ++w) f.records[BrickFields::w0 + w].push_back(bf16_to_float(p.weight[w]));
    f.records[BrickFields::paper_lo].push_back(bf16_to_float(p.paper_lo));
    f.records[BrickFields::paper_hi].push_back(bf16_to_float(p.paper_hi));
    f.records[BrickFields::surplus].push_back(bf16_to_float(p.surplus));
  }
  return f;
}

// The banded build's sink for a store: each brick compacted and compressed on its tile's thread,
// then appended to the file in file order.
class FileSink {
 public:
  FileSink(const StoreLayout& layout, AtomicFile& out, int zstd_level)
      : layout_(layout), out_(out), zstd_level_(zstd_level), entries_(static_cast<size_t>(layout.brick_count())) {}

  using Sections = std::array<std::vector<uint8_t>, kSections>;
  Sections process(int band, const Box3& b, const BandTile& tile) const {
    const int64_t t = layout_.brick_width();
    return encode_brick(layout_, band, brick_fields(tile, {b[0] * t, b[1] * t, b[2] * t}), zstd_level_);
  }
  void commit(int band, const Box3& b, Sections&& sections) {
    BrickEntry& e = entries_[static_cast<size_t>(layout_.brick_index(band, b))];
    e.offset = out_.size();
    for (int s = 0; s < kSections; ++s) {
      const std::vector<uint8_t>& bytes = sections[static_cast<size_t>(s)];
      out_.write(bytes.data(), bytes.size());
      e.bytes[static_cast<size_t>(s)] = static_cast<uint32_t>(bytes.size());
    }
  }
  const std::vector<BrickEntry>& entries() const { return entries_; }

 private:
  const StoreLayout& layout_;
  AtomicFile& out_;
  int zstd_level_;
  std::vector<BrickEntry> entries_;
};

class Converter {
 public:
  Converter(const BoxReader& input, const std::string& output, const ConvertOptions& options)
      : input_(quantized_or(input, options)),
        options_(options),
        layout_(input.info().dims, options.brick_bits),
        out_(output),
        scratch_dir_(std::filesystem::absolute(output).parent_path().string()) {}

  ConvertStats run() {
    const auto start = std::chrono::steady_clock::now();
    const std::array<uint8_t, kHeaderBytes> blank{};
    out_.write(blank.data(), blank.size());
    FileSink sink(layout_, out_, options_.zstd_level);
    BandedBuildOptions build;
    build.memory_bytes = static_cast<uint64_t>(options_.memory_mb) << 20;
    build.progress = options_.progress;
    build.check_cancel = [this] {
      if (options_.cancel && options_.cancel->load()) throw IoError("interrupted");
    };
    // A hand-over stays in memory when it and the band it comes from fit in a quarter of the
    // budget; else it goes to unlinked scratch files beside the output.
    build.make_handover = [this](const Box3& nodes, uint64_t held) -> std::unique_ptr<BandHandover> {
      if (held <= static_cast<uint64_t>(options_.memory_mb) << 18) return nullptr;
      return std::make_unique<ScratchHandover>(scratch_dir_, nodes);
    };
    const ReadBox read = [this](const Box3& lo, const Box3& size, float* out) { input_.read_box(lo, size, out); };
    // What a brick holds between its tile and its commit: at most its raw fields, 30 bytes a node.
    const BandedBuildStats built = build_bands(layout_, read, sink, layout_.brick_nodes() * 30, build);
    finish(sink.entries(), built);
    ConvertStats stats;
    stats.dims = header_.dims;
    stats.type = header_.source_type;
    stats.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    stats.input_bytes = header_.input_bytes;
    stats.output_bytes = out_.size();
    stats.bricks = layout_.brick_count();
    stats.tiles_in_flight = built.tiles_in_flight;
    out_.commit();
    return stats;
  }

 private:
  void finish(const std::vector<BrickEntry>& entries, const BandedBuildStats& built) {
    const VolumeInfo& info = input_.info();
    header_.dims = info.dims;
    header_.spacing = info.spacing;
    header_.origin = info.origin;
    header_.brick_bits = layout_.brick_bits();
    header_.lattice_k = layout_.lattice().k;
    header_.zstd_level = options_.zstd_level;
    header_.source_type = info.type;
    header_.value_min = built.lo;
    header_.value_max = built.hi;
    for (int t = 0; t < 3; ++t) {
      header_.critical_paper[t] = built.critical[0][t];
      header_.critical_exact[t] = built.critical[1][t];
    }
    if (quantized_) {
      header_.quantize_bits = options_.quantize_bits;
      header_.value_offset = quantized_->offset();
      header_.value_min = quantized_->offset();  // the data's range, not the codes'
      header_.value_max = quantized_->max();
      header_.value_scale = quantized_->scale();
    }
    header_.brick_count = layout_.brick_count();
    header_.input_bytes = static_cast<uint64_t>(info.dims[0] * info.dims[1] * info.dims[2] * info.element_bytes);
    for (const Band& band : layout_.bands()) {
      const std::vector<BrickEntry> mine(entries.begin() + band.first_brick,
                                         entries.begin() + band.first_brick + band.brick_count());
      const std::vector<uint8_t> directory = encode_directory(mine);
      BandDirectory& d = header_.bands[static_cast<size_t>(band.scale)];
      d.offset = out_.size();
      d.bytes = directory.size();
      d.checksum = store_checksum(directory.data(), directory.size());
      out_.write(directory.data(), directory.size());
    }
    const auto header = encode_header(header_);
    out_.write_at(0, header.data(), header.size());
  }

  const BoxReader& quantized_or(const BoxReader& input, const ConvertOptions& options) {
    if (options.quantize_bits == 0) return input;
    if (input.info().is_integer)
      throw OptionError("quantize", "applies to float data; integer data is stored losslessly as it is");
    quantized_ = std::make_unique<QuantizingReader>(input, options.quantize_bits, options.cancel);
    return *quantized_;
  }

  std::unique_ptr<QuantizingReader> quantized_;
  const BoxReader& input_;
  const ConvertOptions& options_;
  StoreLayout layout_;
  AtomicFile out_;
  std::string scratch_dir_;
  StoreHeader header_;
};

}  // namespace

ConvertStats convert_to_store(const BoxReader& input, const std::string& output, const ConvertOptions& options) {
  if (options.zstd_level < 1 || options.zstd_level > 19) throw OptionError("zstd-level", "must be 1..19");
  if (options.memory_mb < 1) throw OptionError("memory-mb", "must be at least 1");
  if (options.quantize_bits != 0 && options.quantize_bits != 8 && options.quantize_bits != 16)
    throw OptionError("quantize", "must be 8 or 16");
  if (options.brick_bits < kMinBrickBits || options.brick_bits > kMaxBrickBits)
    throw OptionError("brick-bits", "must be " + std::to_string(kMinBrickBits) + ".." + std::to_string(kMaxBrickBits));
  for (int64_t d : input.info().dims)
    if (d < 2 || d > (int64_t{1} << 19) + 1) throw IoError("volume dimensions must be 2 .. 524289 nodes per axis");
  Converter converter(input, output, options);
  return converter.run();
}

ConvertStats convert(const VolumeSpec& input, const std::string& output, const ConvertOptions& options) {
  check_outputs({{"INPUT", input.path}}, {{"OUTPUT", output}});
  // Scratch beside the output: on the file system the user chose for the store's size.
  const std::string scratch = std::filesystem::absolute(output).parent_path().string();
  const std::unique_ptr<BoxReader> reader = open_box_reader(input, scratch);
  return convert_to_store(*reader, output, options);
}

ConvertStats convert(const Volume& volume, const std::string& output, const ConvertOptions& options) {
  check_outputs({}, {{"OUTPUT", output}});
  validate_volume(volume);
  return convert_to_store(VolumeBoxReader(volume), output, options);
}

}  // namespace isotope
