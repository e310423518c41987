#include "io/store_writer.h"

#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <limits>
#include <memory>
#include <vector>

#include "engine/band_tile.h"
#include "engine/parallel.h"
#include "io/atomic_file.h"
#include "io/io_error.h"
#include "io/scratch_file.h"
#include "io/store_brick.h"
#include "io/store_format.h"

namespace isotope {
namespace {

// What band j hands to band j+1, one entry per node of band j+1's grid, x fastest: the value,
// and the record of the cell's scale-j cube centre.
class BandScratch {
 public:
  BandScratch(const std::string& dir, const Box3& nodes) : nodes_(nodes), values_(dir), children_(dir) {}
  explicit BandScratch(const Box3& nodes)
      : nodes_(nodes), values_(count(nodes) * sizeof(float)), children_(count(nodes) * sizeof(Record)) {}
  static uint64_t count(const Box3& n) { return static_cast<uint64_t>(n[0] * n[1] * n[2]); }
  static uint64_t bytes(const Box3& n) { return count(n) * (sizeof(float) + sizeof(Record)); }

  const Box3& nodes() const { return nodes_; }
  uint64_t at(int64_t x, int64_t y, int64_t z) const {
    return static_cast<uint64_t>((z * nodes_[1] + y) * nodes_[0] + x);
  }
  void write_row(int64_t x0, int64_t y, int64_t z, const std::vector<float>& v, const std::vector<Record>& r) const {
    values_.write(v.data(), v.size() * sizeof(float), at(x0, y, z) * sizeof(float));
    children_.write(r.data(), r.size() * sizeof(Record), at(x0, y, z) * sizeof(Record));
  }
  void read_values(int64_t x0, int64_t count, int64_t y, int64_t z, float* out) const {
    values_.read(out, static_cast<size_t>(count) * sizeof(float), at(x0, y, z) * sizeof(float));
  }
  void read_children(int64_t x0, int64_t count, int64_t y, int64_t z, Record* out) const {
    children_.read(out, static_cast<size_t>(count) * sizeof(Record), at(x0, y, z) * sizeof(Record));
  }

 private:
  Box3 nodes_;
  ScratchFile values_, children_;
};

// Band 0's window: the data box part read from the input, the rest clamped to it.
void fill_from_input(BandTile& tile, const BoxReader& input) {
  const auto& dims = input.info().dims;
  const Box3 lo = tile.window_lo(), hi = tile.window_hi(), size = tile.window_size();
  Box3 rlo, rsize;
  for (int a = 0; a < 3; ++a) {
    rlo[a] = std::min(lo[a], dims[a] - 1);
    rsize[a] = std::min(hi[a], dims[a] - 1) - rlo[a] + 1;
  }
  std::vector<float> box(static_cast<size_t>(rsize[0] * rsize[1] * rsize[2]));
  input.read_box(rlo, rsize, box.data());
  auto& v = tile.values();
  for (int64_t z = 0; z < size[2]; ++z)
    for (int64_t y = 0; y < size[1]; ++y) {
      const int64_t bz = std::min(lo[2] + z, dims[2] - 1) - rlo[2], by = std::min(lo[1] + y, dims[1] - 1) - rlo[1];
      const float* row = box.data() + (bz * rsize[1] + by) * rsize[0];
      float* dst = v.data() + (z * size[1] + y) * size[0];
      for (int64_t x = 0; x < size[0]; ++x) dst[x] = row[std::min(lo[0] + x, dims[0] - 1) - rlo[0]];
    }
}

// Band j > 0's window, from band j-1's scratch: values clamped to the grid, children where they exist.
void fill_from_scratch(BandTile& tile, const BandScratch& in) {
  const Box3& n = in.nodes();
  const Box3 lo = tile.window_lo(), hi = tile.window_hi(), size = tile.window_size();
  const int64_t x0 = std::min(lo[0], n[0] - 1), count = std::min(hi[0], n[0] - 1) - x0 + 1;
  std::vector<float> row(static_cast<size_t>(count));
  auto& v = tile.values();
  for (int64_t z = 0; z < size[2]; ++z)
    for (int64_t y = 0; y < size[1]; ++y) {
      in.read_values(x0, count, std::min(lo[1] + y, n[1] - 1), std::min(lo[2] + z, n[2] - 1), row.data());
      float* dst = v.data() + (z * size[1] + y) * size[0];
      for (int64_t x = 0; x < size[0]; ++x) dst[x] = row[static_cast<size_t>(std::min(lo[0] + x, n[0] - 1) - x0)];
    }
  // Cells of the window whose corner node lies in the grid; the others' centres are beyond
  // record_extent and never read.
  const Box3 cells{size[0] - 1, size[1] - 1, size[2] - 1};
  const int64_t cx = std::min(cells[0], n[0] - lo[0]);
  if (cx <= 0) return;
  auto& c = tile.children();
  for (int64_t z = 0; z < cells[2] && lo[2] + z < n[2]; ++z)
    for (int64_t y = 0; y < cells[1] && lo[1] + y < n[1]; ++y)
      in.read_children(lo[0], cx, lo[1] + y, lo[2] + z, c.data() + (z * cells[1] + y) * cells[0]);
}

void write_next(const BandTile& tile, const BandScratch& next) {
  const Box3 lo = tile.next_lo(), hi = tile.next_hi();
  std::vector<float> v(static_cast<size_t>(std::max<int64_t>(0, hi[0] - lo[0])));
  std::vector<Record> r(v.size());
  if (v.empty()) return;
  for (int64_t z = lo[2]; z < hi[2]; ++z)
    for (int64_t y = lo[1]; y < hi[1]; ++y) {
      for (int64_t x = lo[0]; x < hi[0]; ++x) {
        v[static_cast<size_t>(x - lo[0])] = tile.next_value({x, y, z});
        r[static_cast<size_t>(x - lo[0])] = tile.next_child({x, y, z});
      }
      next.write_row(lo[0], y, z, v, r);
    }
}

// The cells of a grid of `count` per axis in Morton order of their coordinates: bricks of a band
// in file (traversal) order, tiles of bricks, bricks in a tile.
std::vector<Box3> in_morton_order(const Box3& count) {
  std::vector<std::pair<uint64_t, Box3>> order;
  for (int64_t z = 0; z < count[2]; ++z)
    for (int64_t y = 0; y < count[1]; ++y)
      for (int64_t x = 0; x < count[0]; ++x)
        order.push_back({morton_encode(static_cast<uint64_t>(x), static_cast<uint64_t>(y), static_cast<uint64_t>(z)), {x, y, z}});
  std::sort(order.begin(), order.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  std::vector<Box3> out;
  for (const auto& [key, b] : order) out.push_back(b);
  return out;
}

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

struct BrickResult {
  Box3 brick{};
  std::vector<uint8_t> bytes;
  BrickEntry entry;
};

struct TileResult {
  std::vector<BrickResult> bricks;
  CriticalCounts counts = {{0, 0, 0}, {0, 0, 0}};
  float lo = std::numeric_limits<float>::infinity(), hi = -std::numeric_limits<float>::infinity();
};

// Bytes a tile of c^3 bricks holds while in flight: its window (values, records, children),
// one brick being encoded, and the compressed bricks (at most the raw payload each).
int64_t tile_bytes(const StoreLayout& layout, int64_t c) {
  const int64_t w = c * layout.brick_width() + 4;
  const int64_t brick = layout.brick_nodes() * static_cast<int64_t>(2 * sizeof(float) + 2 * sizeof(Record));
  return w * w * w * static_cast<int64_t>(sizeof(float) + 2 * sizeof(Record)) + brick + c * c * c * brick / 2;
}

class Converter {
 public:
  Converter(const BoxReader& input, const std::string& output, const ConvertOptions& options)
      : input_(quantized_or(input, options)), options_(options), layout_(input.info().dims, options.brick_bits), out_(output),
        scratch_dir_(std::filesystem::absolute(output).parent_path().string()) {
    // Tiles of c^3 bricks: larger tiles read their halo and their input rows in fewer, longer
    // calls. The largest c that keeps every thread busy within three quarters of the budget.
    const auto threads = static_cast<int64_t>(
        tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism));
    const int64_t budget = options.memory_mb * (int64_t{3} << 20) / 4;
    // Smaller tiles too when band 0 would not give every thread a few of them.
    const Box3& bricks = layout_.band(0).bricks;
    auto tiles = [&](int64_t c) { return ((bricks[0] + c - 1) / c) * ((bricks[1] + c - 1) / c) * ((bricks[2] + c - 1) / c); };
    for (tile_bricks_ = 4;
         tile_bricks_ > 1 && (budget / tile_bytes(layout_, tile_bricks_) < threads || tiles(tile_bricks_) < 4 * threads);)
      tile_bricks_ /= 2;
    in_flight_ = static_cast<int>(std::clamp<int64_t>(budget / tile_bytes(layout_, tile_bricks_), 1, 2 * threads));
    entries_.resize(static_cast<size_t>(layout_.brick_count()));
  }

  ConvertStats run() {
    const auto start = std::chrono::steady_clock::now();
    const std::array<uint8_t, kHeaderBytes> blank{};
    out_.write(blank.data(), blank.size());
    int64_t work = 0;
    for (const Band& b : layout_.bands()) work += b.nodes[0] * b.nodes[1] * b.nodes[2];
    ProgressReporter progress(options_.progress, work);
    std::unique_ptr<BandScratch> in;
    for (const Band& band : layout_.bands()) {
      std::unique_ptr<BandScratch> next;
      if (band.scale < layout_.lattice().k) {
        // In memory when it and the band it comes from fit in a quarter of the budget; else on
        // disk, where a tile's window costs a read call per row.
        const Box3& nodes = layout_.band(band.scale + 1).nodes;
        const uint64_t held = BandScratch::bytes(nodes) + (in ? BandScratch::bytes(in->nodes()) : 0);
        if (held <= static_cast<uint64_t>(options_.memory_mb) << 18) next = std::make_unique<BandScratch>(nodes);
        else next = std::make_unique<BandScratch>(scratch_dir_, nodes);
      }
      run_band(band, in.get(), next.get(), progress);
      in = std::move(next);
    }
    finish();
    ConvertStats stats;
    stats.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    stats.input_bytes = header_.input_bytes;
    stats.output_bytes = out_.size();
    stats.bricks = layout_.brick_count();
    stats.tiles_in_flight = in_flight_;
    out_.commit();
    return stats;
  }

 private:
  void run_band(const Band& band, const BandScratch* in, const BandScratch* next, ProgressReporter& progress) {
    const int64_t c = tile_bricks_;
    const std::vector<Box3> tiles =
        in_morton_order({(band.bricks[0] + c - 1) / c, (band.bricks[1] + c - 1) / c, (band.bricks[2] + c - 1) / c});
    std::vector<TileResult> results(static_cast<size_t>(in_flight_));
    if (buffers_.empty()) presize_buffers(band);
    for (size_t first = 0; first < tiles.size(); first += results.size()) {
      if (options_.cancel && options_.cancel->load()) throw IoError("interrupted");
      const size_t count = std::min(results.size(), tiles.size() - first);
      parallel_for(int64_t{0}, static_cast<int64_t>(count), [&](int64_t i) {
        const auto slot = static_cast<size_t>(i);
        results[slot] = run_tile(band, tiles[first + slot], in, next, buffers_[slot], progress);
      });
      for (size_t i = 0; i < count; ++i) append(band, results[i]);
    }
  }

  // Band 0 has the largest windows; sized once for them, a slot's arrays never grow again (growing
  // would copy them and fault in fresh pages for every larger tile at the volume's edges).
  void presize_buffers(const Band& band) {
    size_t nodes = 1, cells = 1;
    for (int a = 0; a < 3; ++a) {
      const auto w = static_cast<size_t>(std::min(tile_bricks_ * layout_.brick_width(), band.nodes[a]) + 4);
      nodes *= w;
      cells *= w - 1;
    }
    buffers_.resize(static_cast<size_t>(in_flight_));
    for (BandTile::Buffers& b : buffers_) {
      b.values.resize(nodes);
      b.records.resize(nodes);
      b.children.resize(cells);
    }
  }

  TileResult run_tile(const Band& band, const Box3& tile_coords, const BandScratch* in, const BandScratch* next,
                      BandTile::Buffers& buffers, ProgressReporter& progress) const {
    const int64_t c = tile_bricks_, t = layout_.brick_width();
    Box3 lo, hi;
    for (int a = 0; a < 3; ++a) {
      lo[a] = tile_coords[a] * c * t;
      hi[a] = std::min(lo[a] + c * t, band.nodes[a]);
    }
    TileResult r;
    BandTile tile(layout_, band.scale, lo, hi, std::move(buffers));
    if (in) fill_from_scratch(tile, *in);
    else fill_from_input(tile, input_);
    tile.build(r.counts);
    if (next) write_next(tile, *next);
    if (band.scale == 0) value_range(tile, r);
    // The tile's bricks in Morton order: with aligned power-of-two tiles taken in Morton order,
    // the file holds the band's bricks in Morton order whatever the tile size.
    for (const Box3& l : in_morton_order({c, c, c})) {
      const Box3 b{tile_coords[0] * c + l[0], tile_coords[1] * c + l[1], tile_coords[2] * c + l[2]};
      if (b[0] >= band.bricks[0] || b[1] >= band.bricks[1] || b[2] >= band.bricks[2]) continue;
      BrickResult& out = r.bricks.emplace_back();
      out.brick = b;
      const Box3 origin{b[0] * t, b[1] * t, b[2] * t};
      const BrickContents contents = contents_of(tile, origin, quantized_ ? kQuantizationError : 0.0f);
      out.entry.summary = summarize_brick(contents);
      out.bytes = band.scale == 0 ? encode_brick(halo_values_of(tile, origin), {}, options_.zstd_level, out.entry)
                                  : encode_brick(contents.values, contents.records, options_.zstd_level, out.entry);
    }
    progress.advance((hi[0] - lo[0]) * (hi[1] - lo[1]) * (hi[2] - lo[2]));
    buffers = tile.release();
    return r;
  }

  void value_range(const BandTile& tile, TileResult& r) const {
    const auto& d = layout_.dims();
    for (int64_t z = tile.core_lo()[2]; z < std::min(tile.core_hi()[2], d[2]); ++z)
      for (int64_t y = tile.core_lo()[1]; y < std::min(tile.core_hi()[1], d[1]); ++y)
        for (int64_t x = tile.core_lo()[0]; x < std::min(tile.core_hi()[0], d[0]); ++x) {
          const float v = tile.node_value({x, y, z});
          r.lo = std::min(r.lo, v);
          r.hi = std::max(r.hi, v);
        }
  }

  void append(const Band& band, TileResult& r) {
    for (BrickResult& b : r.bricks) {
      b.entry.offset = out_.size();
      out_.write(b.bytes.data(), b.bytes.size());
      entries_[static_cast<size_t>(layout_.brick_index(band.scale, b.brick))] = b.entry;
    }
    for (int t = 0; t < 3; ++t) {
      header_.critical_paper[t] += r.counts[0][t];
      header_.critical_exact[t] += r.counts[1][t];
    }
    lo_ = std::min(lo_, r.lo);
    hi_ = std::max(hi_, r.hi);
  }

  void finish() {
    const VolumeInfo& info = input_.info();
    header_.dims = info.dims;
    header_.spacing = info.spacing;
    header_.origin = info.origin;
    header_.brick_bits = layout_.brick_bits();
    header_.lattice_k = layout_.lattice().k;
    header_.zstd_level = options_.zstd_level;
    header_.source_type = info.type;
    header_.value_min = lo_;
    header_.value_max = hi_;
    if (quantized_) {
      header_.quantize_bits = options_.quantize_bits;
      header_.value_offset = quantized_->offset();
      header_.value_min = quantized_->offset();  // the data's range, not the codes'
      header_.value_max = quantized_->max();
      header_.value_scale = quantized_->scale();
    }
    header_.brick_count = layout_.brick_count();
    header_.input_bytes = static_cast<uint64_t>(info.dims[0] * info.dims[1] * info.dims[2] * info.element_bytes);
    const std::vector<uint8_t> directory = encode_directory(entries_);
    header_.directory_offset = out_.size();
    header_.directory_bytes = directory.size();
    header_.directory_checksum = store_checksum(directory.data(), directory.size());
    out_.write(directory.data(), directory.size());
    const auto header = encode_header(header_);
    out_.write_at(0, header.data(), header.size());
  }

  const BoxReader& quantized_or(const BoxReader& input, const ConvertOptions& options) {
    if (options.quantize_bits == 0) return input;
    if (input.info().is_integer)
      throw IoError("--quantize applies to float data; integer data is stored losslessly as it is");
    quantized_ = std::make_unique<QuantizingReader>(input, options.quantize_bits, options.cancel);
    return *quantized_;
  }

  std::unique_ptr<QuantizingReader> quantized_;
  const BoxReader& input_;
  const ConvertOptions& options_;
  StoreLayout layout_;
  AtomicFile out_;
  std::string scratch_dir_;
  std::vector<BandTile::Buffers> buffers_;  // one per tile in flight
  int64_t tile_bricks_ = 1;
  int in_flight_ = 1;
  std::vector<BrickEntry> entries_;
  StoreHeader header_;
  float lo_ = std::numeric_limits<float>::infinity(), hi_ = -std::numeric_limits<float>::infinity();
};

}  // namespace

ConvertStats convert_to_store(const BoxReader& input, const std::string& output, const ConvertOptions& options) {
  if (options.zstd_level < 1 || options.zstd_level > 19) throw IoError("--zstd-level must be 1..19");
  if (options.memory_mb < 1) throw IoError("--memory-mb must be at least 1");
  if (options.quantize_bits != 0 && options.quantize_bits != 8 && options.quantize_bits != 16)
    throw IoError("--quantize must be 8 or 16");
  for (int64_t d : input.info().dims)
    if (d < 2 || d > (int64_t{1} << 19) + 1)
      throw IoError("volume dimensions must be 2 .. 524289 nodes per axis");
  Converter converter(input, output, options);
  return converter.run();
}

}  // namespace isotope
