#include "io/store/store_writer.h"

#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <limits>
#include <memory>
#include <new>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "engine/core/byte_codec.h"
#include "engine/core/parallel.h"
#include "engine/core/volume_check.h"
#include "engine/hierarchy/band_tile.h"
#include "engine/hierarchy/banded_build.h"
#include "engine/hierarchy/compact_record.h"
#include "io/file/atomic_file.h"
#include "io/file/scratch_file.h"
#include "io/file/shared_file.h"
#include "io/store/handover_file.h"
#include "io/store/store_format.h"
#include "io/volume/held_box_reader.h"
#include "io/volume/volume_box_reader.h"
#include "isotope/error.h"

namespace isotope {

namespace {

// A hand-over smaller than this stays in memory (build_options).
constexpr uint64_t kHandoverInMemoryBelow = uint64_t{16} << 20;

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
  bool reads_box_alone() const override { return input_.reads_box_alone(); }
  bool in_memory() const override { return input_.in_memory(); }
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
// (docs/FORMAT.md, "Compact records"). Band 0 and the corners: values only. Into `f`, a thread's
// own, whose arrays keep their size from brick to brick: a brick within the band's grid writes
// every entry, so that only one past it (nodes beyond the grid: 0 in every field) fills them first.
// Without `topology`, the records' core fields alone (lo, hi, bound: a store without sections of
// their topology, StoreSections).
void brick_fields(const BandTile& tile, const Box3& origin, BrickFields& f, bool topology) {
  const StoreLayout& layout = tile.layout();
  const int j = tile.band();
  const Band& band = layout.band(j);
  const int64_t t = layout.brick_width();
  const auto nodes = static_cast<uint32_t>(layout.brick_nodes());
  // Walked row by row of the tile's window (x fastest), written at each node's Morton position.
  const Box3 end{std::min(t, band.nodes[0] - origin[0]), std::min(t, band.nodes[1] - origin[1]),
                 std::min(t, band.nodes[2] - origin[2])};
  const bool whole = end[0] == t && end[1] == t && end[2] == t;
  auto size = [&](std::vector<float>& field, size_t n) {
    if (whole)
      field.resize(n);
    else
      field.assign(n, 0.0f);
  };
  size(f.values, nodes);
  const uint32_t* const sx = kSpreadBits3.data();
  for (int64_t z = 0; z < end[2]; ++z)
    for (int64_t y = 0; y < end[1]; ++y) {
      const uint32_t yz = sx[y] << 1 | sx[z] << 2;
      const float* row = &tile.node_value({origin[0], origin[1] + y, origin[2] + z});
      float* const values = f.values.data();
      for (int64_t x = 0; x < end[0]; ++x) values[yz | sx[x]] = row[x];
    }
  if (!stores_records(layout, j)) {
    for (auto& field : f.records) field.clear();
    return;
  }
  // Nodes beyond the band's grid: 0 in every field. Walked row by row (the tile's records in
  // memory order), each written at its place among the brick's nodes with records: Morton order
  // without the nodes whose three coordinates are even (m & 7 == 0), i = m - m / 8 - 1.
  std::array<float*, BrickFields::count> out;
  const size_t held = topology ? out.size() : BrickFields::bound + 1;
  for (size_t k = 0; k < held; ++k) {
    size(f.records[k], nodes - nodes / 8);
    out[k] = f.records[k].data();
  }
  for (int64_t z = 0; z < end[2]; ++z)
    for (int64_t y = 0; y < end[1]; ++y) {
      const uint32_t yz = sx[y] << 1 | sx[z] << 2;
      const Record* row = &tile.node_record({origin[0], origin[1] + y, origin[2] + z});
      for (int64_t x = 0; x < end[0]; ++x) {
        const uint32_t m = yz | sx[x];
        if ((m & 7) == 0) continue;
        const size_t i = m - m / 8 - 1;
        const Record& r = row[x];
        const PackedBounds b = pack_bounds(r.bounds);
        out[BrickFields::lo][i] = bf16_to_float(b.lo);
        out[BrickFields::hi][i] = bf16_to_float(b.hi);
        out[BrickFields::bound][i] = b.bound;
        if (!topology) continue;
        const PackedTopology p = pack_topology(r.topology, r.bounds.error_surplus);
        out[BrickFields::exact_lo][i] = bf16_to_float(p.exact_lo);
        out[BrickFields::exact_hi][i] = bf16_to_float(p.exact_hi);
        for (int w = 0; w < 3; ++w) out[BrickFields::w0 + w][i] = bf16_to_float(p.weight[w]);
        out[BrickFields::paper_lo][i] = bf16_to_float(p.paper_lo);
        out[BrickFields::paper_hi][i] = bf16_to_float(p.paper_hi);
        out[BrickFields::surplus][i] = bf16_to_float(p.surplus);
      }
    }
}

// Where a sink's bricks go: the store's file, or (a distributed convert's rank > 0) an unlinked
// scratch file of its own, copied into the store once the ranks before it know their sizes; and,
// in a distributed pass of two bands, every rank's bricks of the upper band.
class ScratchOut {
 public:
  explicit ScratchOut(const std::string& dir) : file_(dir) {}
  void write(const void* data, size_t bytes) {
    file_.write(data, bytes, size_);
    size_ += bytes;
  }
  uint64_t size() const { return size_; }
  // Copies everything written into `to` at `offset`.
  void copy_to(const SharedFile& to, uint64_t offset) const { copy_to(0, size_, to, offset); }
  // Copies `bytes` from `from` on into `to` at `offset`, a few MiB at a time.
  void copy_to(uint64_t from, uint64_t bytes, const SharedFile& to, uint64_t offset) const {
    std::vector<char> buf(static_cast<size_t>(std::min<uint64_t>(bytes, uint64_t{8} << 20)));
    for (uint64_t at = 0; at < bytes; at += buf.size()) {
      const size_t n = static_cast<size_t>(std::min<uint64_t>(buf.size(), bytes - at));
      file_.read(buf.data(), n, from + at);
      to.write(buf.data(), n, offset + at);
    }
  }

 private:
  ScratchFile file_;
  uint64_t size_ = 0;
};

// The banded build's sink for a store: each brick compacted and compressed on its tile's thread,
// then appended to the file in file order.
template <class Out>
class FileSink {
 public:
  FileSink(const StoreLayout& layout, Out& out, int zstd_level, std::string scratch_dir,
           const StoreSections& sections = kAllSections)
      : layout_(layout),
        out_(out),
        zstd_level_(zstd_level),
        scratch_dir_(std::move(scratch_dir)),
        sections_(sections),
        entries_(static_cast<size_t>(layout.brick_count())) {}

  using Sections = std::array<std::vector<uint8_t>, kSections>;
  Sections process(int band, const Box3& b, const BandTile& tile) const {
    const int64_t t = layout_.brick_width();
    thread_local BrickFields fields;
    brick_fields(tile, {b[0] * t, b[1] * t, b[2] * t}, fields, with_topology(sections_));
    return encode_brick(layout_, band, fields, zstd_level_, sections_);
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
  // The bricks of a band built beside the one before it (a fused pass), which come before that
  // band's last: in an unlinked scratch file until release() appends them in file order (Morton
  // order: those at the grid's far faces come with the tiles before them).
  void hold(int band, const Box3& b, Sections&& sections) {
    if (!held_file_) held_file_.emplace(scratch_dir_);
    const int64_t index = layout_.brick_index(band, b);
    BrickEntry& e = entries_[static_cast<size_t>(index)];
    e.offset = held_bytes_;
    for (int s = 0; s < kSections; ++s) {
      const std::vector<uint8_t>& bytes = sections[static_cast<size_t>(s)];
      held_file_->write(bytes.data(), bytes.size(), held_bytes_);
      held_bytes_ += bytes.size();
      e.bytes[static_cast<size_t>(s)] = static_cast<uint32_t>(bytes.size());
    }
    held_.push_back(
        {morton_encode(static_cast<uint64_t>(b[0]), static_cast<uint64_t>(b[1]), static_cast<uint64_t>(b[2])), index});
  }
  // A distributed convert's pair of bands: release() appends the held bricks to `to` instead,
  // their entries' offsets counted from its start; the ranks place them (Converter::run_shared).
  void release_to(ScratchOut* to) { release_to_ = to; }
  void release() {
    std::sort(held_.begin(), held_.end());
    // Runs of bricks that lie one after the other in the scratch file (nearly all), a few MiB a call.
    std::vector<char> buf;
    for (size_t i = 0; i < held_.size();) {
      const uint64_t from = entry(held_[i]).offset;
      uint64_t to = from;
      size_t end = i;
      for (; end < held_.size() && entry(held_[end]).offset == to && to - from < (uint64_t{8} << 20); ++end)
        for (uint32_t bytes : entry(held_[end]).bytes) to += bytes;
      buf.resize(static_cast<size_t>(to - from));
      held_file_->read(buf.data(), buf.size(), from);
      const uint64_t at = release_to_ ? release_to_->size() : out_.size();
      for (size_t m = i; m < end; ++m) entry(held_[m]).offset += at - from;
      if (release_to_)
        release_to_->write(buf.data(), buf.size());
      else
        out_.write(buf.data(), buf.size());
      i = end;
    }
    held_.clear();
    held_file_.reset();
    held_bytes_ = 0;
  }
  std::vector<BrickEntry>& entries() { return entries_; }

 private:
  BrickEntry& entry(const std::pair<uint64_t, int64_t>& held) { return entries_[static_cast<size_t>(held.second)]; }
  const StoreLayout& layout_;
  Out& out_;
  int zstd_level_;
  std::string scratch_dir_;
  StoreSections sections_;
  std::vector<BrickEntry> entries_;
  std::optional<ScratchFile> held_file_;
  uint64_t held_bytes_ = 0;
  std::vector<std::pair<uint64_t, int64_t>> held_;  // Morton code, brick index
  ScratchOut* release_to_ = nullptr;
};

// A brick's directory entry as a rank of a distributed convert hands it to rank 0.
struct PlacedEntry {
  int64_t index;
  BrickEntry entry;
};

// A run of bricks of consecutive Morton codes in one band, as a rank of a distributed convert
// tells the others where they lie in its scratch file.
struct BrickRun {
  uint64_t code;   // the first brick's
  uint64_t count;  // bricks
  uint64_t bytes;
};

// One of this rank's runs: where it lies in the rank's scratch file and goes in the store, and its
// bricks' directory indices in order.
struct TopRun {
  BrickRun run;
  uint64_t from = 0, to = 0;
  std::vector<int64_t> bricks;
};

// What one rank of a distributed convert tells the others after each pass.
struct BandShare {
  uint64_t bytes = 0;
  CriticalCounts critical = {{0, 0, 0}, {0, 0, 0}};
  float lo = 0, hi = 0;
};

class Converter {
 public:
  Converter(const BoxReader& input, const std::string& output, const ConvertCall& options, StoreLife life,
            const StoreSections& sections)
      : input_(quantized_or(input, options)),
        options_(options),
        life_(life),
        sections_(sections),
        layout_(input.info().dims, options.brick_bits),
        output_(output),
        scratch_dir_(std::filesystem::absolute(output).parent_path().string()) {}

  ConvertStats run() {
    const auto start = std::chrono::steady_clock::now();
    BandedBuildStats built;
    if (options_.distribution)
      built = run_shared(*options_.distribution);
    else
      built = run_alone();
    ConvertStats stats;
    stats.dims = layout_.dims();
    stats.type = input_.info().type;
    stats.input_bytes = input_bytes();
    stats.bricks = layout_.brick_count();
    stats.tiles_in_flight = built.tiles_in_flight;
    stats.bands_built_beside = built.bands_built_beside;
    stats.input_held_bytes = input_held_bytes_;
    if (out_) stats.output_bytes = out_->size();  // this process wrote the store (alone, or rank 0)
    auto commit = [this] {
      if (out_) out_->commit();
    };
    settle_together(options_.distribution, commit);  // a rename that fails on rank 0 fails every rank
    stats.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return stats;
  }

 private:
  BandedBuildOptions build_options() {
    BandedBuildOptions build;
    build.memory_bytes = budget_bytes();
    // A stage gathers the reads of a group of tiles into one: worth it where a box costs more
    // than its bytes (strips or chunks decoded again for each tile). For raw data it saved only
    // part of the rows' gaps, and its groups ended in waits for their slowest tile: a 2048^3
    // convert took 158.7 s with it, 140.7 s without (a hand-over in a file costs a call a cube
    // whether staged or not).
    build.staged = !input_.reads_box_alone();
    build.fuse = true;  // a hand-over that would be a scratch file: built beside instead
    build.topology = with_topology(sections_);
    build.weights = sections_[static_cast<size_t>(Section::weights)];
    build.progress = options_.progress;
    build.check_cancel = [this] {
      if (options_.cancel && options_.cancel->load()) throw IoError("interrupted");
    };
    // A hand-over of more than a few MB goes to unlinked scratch files beside the output. One
    // that fits in a quarter of the budget with the band it comes from is kept there, never built
    // beside (fuse): written and read back by the kernel through the page cache, it costs less
    // than the process's own first writes into fresh memory (docs/METHOD.md, "Fresh memory"), and
    // less than a fused pass's halo at those sizes (docs/FORMAT.md, "How convert bounds its
    // memory"). A smaller one stays in memory: its pages cost a few milliseconds either way, and
    // a file's cubes of entries would pad it (a 33^3 hand-over takes 48^3 entries' room). So
    // does one that fits where its files find no room (a full disk, a file size limit): a volume
    // whose hand-overs fit the budget needs no room beside its output but the store's.
    build.make_handover = [this](const Box3& nodes, uint64_t held) -> std::unique_ptr<BandHandover> {
      const bool fits = held <= budget_bytes() / 4;
      if (!fits) return std::make_unique<ScratchHandover>(scratch_dir_, nodes);
      if (BandHandover::bytes(nodes) < kHandoverInMemoryBelow) return nullptr;
      try {
        auto files = std::make_unique<ScratchHandover>(scratch_dir_, nodes, true);
        if (files->reserve()) return files;
      } catch (const IoError&) {  // no scratch file at all
      }
      return nullptr;
    };
    return build;
  }
  // The budget's bytes, less those of the input held whole (run_alone).
  uint64_t budget_bytes() const { return (static_cast<uint64_t>(options_.memory_mb) << 20) - input_held_bytes_; }
  static ReadBox reader(const BoxReader& input) {
    return [&input](const Box3& lo, const Box3& size, float* out) { input.read_box(lo, size, out); };
  }
  // What a brick holds between its tile and its commit: at most its raw fields, 30 bytes a node.
  int64_t sink_brick_bytes() const { return layout_.brick_nodes() * 30; }

  BandedBuildStats run_alone() {
    // Written once, start to end.
    out_.emplace(output_, life_ == StoreLife::kept ? AtomicFile::Appends::direct : AtomicFile::Appends::transient);
    const std::array<uint8_t, kHeaderBytes> blank{};
    out_->write(blank.data(), blank.size());
    FileSink<AtomicFile> sink(layout_, *out_, options_.zstd_level, scratch_dir_, sections_);
    // A volume file that a quarter of the budget holds is read once and held (HeldBoxReader), the
    // rest of the budget left to the build; the tiles' boxes, read each on its own, would copy
    // most of the file out of the page cache several times (docs/METHOD.md, "The input held
    // whole"). Not under a distribution, where each process reads only its share of the tiles.
    std::optional<HeldBoxReader> held;
    const uint64_t memory = static_cast<uint64_t>(options_.memory_mb) << 20;
    const uint64_t held_bytes = HeldBoxReader::held_bytes(input_);
    if (input_.reads_box_alone() && !input_.in_memory() && held_bytes <= memory / 4) {
      try {
        held.emplace(input_);
        input_held_bytes_ = held_bytes;
      } catch (const std::bad_alloc&) {  // read box by box instead, as a larger volume is
      }
    }
    const BandedBuildStats built =
        build_bands(layout_, reader(held ? *held : input_), sink, sink_brick_bytes(), build_options());
    held.reset();  // the input is read by band 0 alone
    finish(sink.entries(), built);
    return built;
  }

  // The distributed convert (isotope/distribution.h; docs/DISTRIBUTED.md), a pass a
  // band or, where the tiles allow, two bands a pass (j and j+1, as one process fuses them):
  //  1. rank 0 creates the output's temporary file; the ranks agree on the tile size (the
  //     smallest any of them would choose), so that the tiles are the same on all;
  //  2. band j's tiles, in Morton order, are cut into one contiguous run per rank, about equal in
  //     nodes (tile_costs), whose bricks are hence a contiguous run of the file: rank 0 appends
  //     its own to the file, every other rank to an unlinked scratch file of its own; band j+1's
  //     bricks (a pair's) go to another scratch file; all write their tiles' rows of the pass's
  //     hand-over, a named file beside the output, which the next pass reads whole;
  //  3. an exclusive scan of the ranks' byte counts places each run of band j; band j+1's bricks
  //     are placed from the runs of consecutive Morton codes every rank tells all (BrickRun: its
  //     first code, bricks and bytes); the ranks copy theirs in and hand rank 0 their bricks'
  //     directory entries;
  //  4. after the last band rank 0 writes the directories and the header.
  // Every step that may fail on one rank alone runs under settle_together: all stop together,
  // and rank 0's temporary files are removed as it unwinds. Coarse bands with fewer tiles than
  // ranks leave some ranks idle; the last bands are a few bricks.
  BandedBuildStats run_shared(const Distribution& group) {
    SharedRun run(group);
    begin_shared(run);  // 1
    for (int j = 0; j <= layout_.lattice().k;) {
      SharedPass pass;
      open_pass(run, j, pass);
      const BandShare share = build_share(run, pass);  // 2
      place_share(run, pass, share);                   // 3
      if (pass.pair) place_top_runs(run, pass);
      copy_into_place(run, pass);
      gather_entries(run, pass);
      run.end += pass.band_bytes + pass.top_bytes;
      run.in = std::move(pass.next);  // band top's hand-over, read by band top + 1 (rank 0's removes its file)
      j = pass.top + 1;
    }
    settle_together(group, [&] {  // 4
      if (!run.root) return;
      out_->continue_at(run.end);
      finish(run.entries, run.stats);
      out_->finish();
    });
    return run.stats;
  }

  // What the passes of a distributed convert share.
  struct SharedRun {
    explicit SharedRun(const Distribution& g) : group(g), root(g.rank() == 0), r(static_cast<size_t>(g.rank())) {}
    const Distribution& group;
    bool root;
    size_t r;                        // this rank
    int64_t c = 0;                   // tiles of c^3 bricks, the same on every rank
    bool pairs = false;              // bands two to a pass (BandedBuildOptions::fuse_pair)
    std::string temp_path;           // rank 0's temporary output
    std::optional<SharedFile> temp;  // that file, as the other ranks write into it
    BandedBuildStats stats;
    std::vector<BrickEntry> entries;  // every brick's, once placed
    uint64_t end = kHeaderBytes;      // where the next band's bricks begin
    std::unique_ptr<SharedHandover> in;
  };
  // One pass: band j, or bands j and top = j + 1.
  struct SharedPass {
    int j = 0, top = 0;
    bool pair = false, last = false;
    std::unique_ptr<SharedHandover> next;  // the hand-over to band top + 1
    std::optional<ScratchOut> scratch;     // a rank > 0's bricks of band j
    std::optional<ScratchOut> held;        // a pair's band top, in Morton order
    uint64_t offset = 0;                   // where this rank's run of band j goes
    uint64_t band_bytes = 0, top_bytes = 0;
    std::vector<TopRun> top_mine;  // this rank's runs of band top, in file (Morton) order
  };

  // Rank 0 creates the output's temporary file; the ranks agree on the tile size (the smallest
  // any of them would choose), so that the tiles are the same on all, and on whether bands go two
  // to a pass: under mpirun every hand-over is a shared file, and a pair's is never made.
  void begin_shared(SharedRun& run) {
    const Distribution& group = run.group;
    settle_together(group, [&] {
      if (!run.root) return;
      out_.emplace(output_);
      const std::array<uint8_t, kHeaderBytes> blank{};
      out_->write(blank.data(), blank.size());
      out_->continue_at(kHeaderBytes);  // flushed: the file exists with its header's room
    });
    ByteWriter mine;
    const uint64_t memory = static_cast<uint64_t>(options_.memory_mb) << 20;
    mine.put(fused_tile_bricks_for(layout_, sink_brick_bytes(), memory));
    mine.put(tile_bricks_for(layout_, sink_brick_bytes(), memory));
    mine.put_array(run.root ? out_->temp_path() : std::string());
    int64_t fused = INT64_MAX, c = INT64_MAX;
    for (const std::vector<uint8_t>& bytes : group.all_gather(mine.bytes())) {
      ByteReader rd(bytes);
      fused = std::min(fused, rd.get<int64_t>());  // 0 where a rank cannot fuse
      c = std::min(c, rd.get<int64_t>());
      std::string path;
      rd.get_array(path);
      if (!path.empty()) run.temp_path = path;
    }
    run.pairs = fused > 0;
    run.c = run.pairs ? fused : c;
    settle_together(group, [&] {
      if (!run.root) run.temp.emplace(run.temp_path, SharedFile::Mode::open);
    });
    run.entries.resize(static_cast<size_t>(layout_.brick_count()));
  }

  // The pass from band j, and its hand-over to band top + 1: created by rank 0, opened by the
  // others once it exists (build_share).
  void open_pass(const SharedRun& run, int j, SharedPass& pass) {
    pass.j = j;
    pass.pair = run.pairs && j + 1 <= layout_.lattice().k;
    pass.top = pass.pair ? j + 1 : j;  // the last band of this pass
    pass.last = pass.top == layout_.lattice().k;
    settle_together(run.group, [&] {
      if (run.root && !pass.last)
        pass.next = std::make_unique<SharedHandover>(next_handover_path(run, pass), SharedFile::Mode::create,
                                                     layout_.band(pass.top + 1).nodes);
    });
  }
  std::string next_handover_path(const SharedRun& run, const SharedPass& pass) const {
    return run.temp_path + ".band" + std::to_string(pass.top + 1);
  }

  // This rank's contiguous run of the band's tiles in Morton order (about equal in nodes across
  // the ranks, tile_costs), built: rank 0 appends its bricks to the file, every other rank to a
  // scratch file of its own; a pair's band top goes to another scratch file; all write their
  // tiles' rows of the hand-over.
  BandShare build_share(SharedRun& run, SharedPass& pass) {
    const Band& band = layout_.band(pass.j);
    const std::vector<size_t> shares = share_by_cost(tile_costs(layout_, band, run.c), run.group.ranks());
    BandShare share;
    settle_together(run.group, [&] {
      if (!run.root && !pass.last)
        pass.next = std::make_unique<SharedHandover>(next_handover_path(run, pass), SharedFile::Mode::open,
                                                     layout_.band(pass.top + 1).nodes);
      BandedBuildOptions build = build_options();
      if (pass.j > 0)
        build.progress =
            nullptr;  // band 0's pass is 7/8 of the work (with band 1, 63/64): its progress is the convert's
      build.first_band = pass.j;
      build.last_band = pass.top;
      build.fuse_pair = pass.pair;
      build.first_tile = shares[run.r];
      build.last_tile = shares[run.r + 1];
      build.tile_bricks = run.c;
      build.handover_in = run.in.get();
      build.handover_out = pass.next.get();
      if (pass.pair) pass.held.emplace(scratch_dir_);
      BandedBuildStats built;
      auto build_into = [&](auto& sink) {
        if (pass.pair) sink.release_to(&*pass.held);
        built = build_bands(layout_, reader(input_), sink, sink_brick_bytes(), build);
        for (int b = pass.j; b <= pass.top; ++b) take_band(sink.entries(), layout_.band(b), run.entries);
      };
      if (run.root) {
        out_->continue_at(run.end);
        FileSink<AtomicFile> sink(layout_, *out_, options_.zstd_level, scratch_dir_, sections_);
        build_into(sink);
        share.bytes = out_->size() - run.end;
      } else {
        pass.scratch.emplace(scratch_dir_);
        FileSink<ScratchOut> sink(layout_, *pass.scratch, options_.zstd_level, scratch_dir_, sections_);
        build_into(sink);
        share.bytes = pass.scratch->size();
      }
      for (int m = 0; m < 2; ++m)
        for (int t = 0; t < 3; ++t) share.critical[m][t] = built.critical[m][t];
      share.lo = built.lo;
      share.hi = built.hi;
      run.stats.tiles_in_flight = std::max(run.stats.tiles_in_flight, built.tiles_in_flight);
      run.stats.bands_built_beside += built.bands_built_beside;
    });
    return share;
  }

  // The exclusive scan of the runs' sizes, which places this rank's run of band j, and the
  // totals of what the band counted.
  void place_share(SharedRun& run, SharedPass& pass, const BandShare& mine) {
    ByteWriter told;
    told.put(mine);
    pass.offset = run.end;
    const std::vector<std::vector<uint8_t>> all = run.group.all_gather(told.bytes());
    for (size_t i = 0; i < all.size(); ++i) {
      ByteReader rd(all[i]);
      const auto s = rd.get<BandShare>();
      if (i < run.r) pass.offset += s.bytes;
      pass.band_bytes += s.bytes;
      for (int m = 0; m < 2; ++m)
        for (int t = 0; t < 3; ++t) run.stats.critical[m][t] += s.critical[m][t];
      run.stats.lo = std::min(run.stats.lo, s.lo);
      run.stats.hi = std::max(run.stats.hi, s.hi);
    }
  }

  // A pair's band top follows band j. A rank's bricks of it are not one run of the file (those at
  // the grid's far faces come with the tiles before them): the ranks tell each other their runs of
  // consecutive Morton codes and each run's bytes (a run for each part of a rank's tiles, and one
  // for each brick at the grid's far faces), and so each learns where its own go.
  void place_top_runs(SharedRun& run, SharedPass& pass) {
    const Distribution& group = run.group;
    ByteWriter told_runs;
    settle_together(group, [&] {
      const Band& up = layout_.band(pass.top);
      std::vector<std::pair<uint64_t, int64_t>> mine_top;  // Morton code, directory index
      for (int64_t i = up.first_brick; i < up.first_brick + up.brick_count(); ++i) {
        if (run.entries[static_cast<size_t>(i)].total() == 0) continue;  // not this rank's
        const Box3 b = StoreLayout::brick_of(up, i);
        mine_top.push_back(
            {morton_encode(static_cast<uint64_t>(b[0]), static_cast<uint64_t>(b[1]), static_cast<uint64_t>(b[2])), i});
      }
      std::sort(mine_top.begin(), mine_top.end());
      std::vector<BrickRun> runs;
      for (const auto& [code, i] : mine_top) {
        const BrickEntry& e = run.entries[static_cast<size_t>(i)];
        if (pass.top_mine.empty() || code != pass.top_mine.back().run.code + pass.top_mine.back().run.count)
          pass.top_mine.push_back({{code, 0, 0}, e.offset, 0, {}});
        TopRun& t = pass.top_mine.back();
        ++t.run.count;
        t.run.bytes += e.total();
        t.bricks.push_back(i);
      }
      for (const TopRun& t : pass.top_mine) runs.push_back(t.run);
      told_runs.put_array(runs);
    });
    const std::vector<std::vector<uint8_t>> all_runs = group.all_gather(told_runs.bytes());
    settle_together(group, [&] {
      std::vector<std::pair<BrickRun, size_t>> every;  // a run, and its rank
      for (size_t rank = 0; rank < all_runs.size(); ++rank) {
        ByteReader rd(all_runs[rank]);
        std::vector<BrickRun> theirs;
        rd.get_array(theirs);
        for (const BrickRun& brick_run : theirs) every.push_back({brick_run, rank});
      }
      std::sort(every.begin(), every.end(), [](const auto& u, const auto& v) { return u.first.code < v.first.code; });
      uint64_t at = run.end + pass.band_bytes;
      int64_t bricks = 0;
      size_t n = 0;  // this rank's runs met so far, in order
      for (const auto& [brick_run, rank] : every) {
        if (rank == run.r) pass.top_mine[n++].to = at;
        at += brick_run.bytes;
        bricks += static_cast<int64_t>(brick_run.count);
      }
      if (bricks != layout_.band(pass.top).brick_count())
        throw IoError(output_ + ": the ranks' band " + std::to_string(pass.top) + " holds " + std::to_string(bricks) +
                      " bricks, not " + std::to_string(layout_.band(pass.top).brick_count()));
      pass.top_bytes = at - (run.end + pass.band_bytes);
    });
  }

  // Ranks > 0 copy their run into place, every rank its runs of a pair's band top.
  void copy_into_place(SharedRun& run, SharedPass& pass) {
    settle_together(run.group, [&] {
      const Band& band = layout_.band(pass.j);
      for (int64_t i = band.first_brick; i < band.first_brick + band.brick_count(); ++i) {
        BrickEntry& e = run.entries[static_cast<size_t>(i)];
        if (e.total() == 0) continue;            // not this rank's
        if (!run.root) e.offset += pass.offset;  // was relative to the rank's scratch file
      }
      if (pass.pair) {
        std::optional<SharedFile> own;  // rank 0's file, written where its appends do not reach
        if (run.root) own.emplace(out_->temp_path(), SharedFile::Mode::open);
        for (const TopRun& t : pass.top_mine) {
          uint64_t at = t.to;
          for (const int64_t i : t.bricks) {
            BrickEntry& e = run.entries[static_cast<size_t>(i)];
            e.offset = at;
            at += e.total();
          }
          pass.held->copy_to(t.from, t.run.bytes, run.root ? *own : *run.temp,
                             t.to);  // one after the other in `held` too
        }
      }
      if (!run.root) {
        // Its bricks are durable when rank 0 commits the store (rank 0's fsync covers only its own
        // node's writes). The hand-over is not synced: a POSIX-coherent file system (Lustre,
        // GPFS, BeeGFS, or one node's) shows other ranks its rows without (docs/DISTRIBUTED.md).
        pass.scratch->copy_to(*run.temp, pass.offset);
        run.temp->sync();
      }
    });
  }

  // Every rank tells rank 0 where its bricks are.
  void gather_entries(SharedRun& run, const SharedPass& pass) {
    ByteWriter placed;
    settle_together(run.group, [&] {
      std::vector<PlacedEntry> mine, mine_top;
      const Band& band = layout_.band(pass.j);
      for (int64_t i = band.first_brick; i < band.first_brick + band.brick_count(); ++i)
        if (run.entries[static_cast<size_t>(i)].total() != 0) mine.push_back({i, run.entries[static_cast<size_t>(i)]});
      for (const TopRun& t : pass.top_mine)
        for (const int64_t i : t.bricks) mine_top.push_back({i, run.entries[static_cast<size_t>(i)]});
      placed.put_array(mine);
      placed.put_array(mine_top);
    });
    std::vector<std::vector<uint8_t>> where;
    settle_together(run.group,
                    [&] { where = run.group.gather(placed.bytes()); });  // rank 0 may run out of memory receiving
    settle_together(run.group, [&] {
      if (!run.root) return;
      std::vector<std::vector<PlacedEntry>> runs(where.size()), runs_top(where.size());
      for (size_t i = 0; i < where.size(); ++i) {
        ByteReader rd(where[i]);
        rd.get_array(runs[i]);
        rd.get_array(runs_top[i]);
      }
      place_band(runs, layout_.band(pass.j), run.entries);
      if (pass.pair) place_band(runs_top, layout_.band(pass.top), run.entries);
    });
  }

  // A sink's entries of one band into `entries` (the others' are still empty there).
  static void take_band(const std::vector<BrickEntry>& from, const Band& band, std::vector<BrickEntry>& entries) {
    std::copy(from.begin() + band.first_brick, from.begin() + band.first_brick + band.brick_count(),
              entries.begin() + band.first_brick);
  }

  // Rank 0: every rank's entries of the band, each at its directory index; every brick from
  // exactly one rank.
  void place_band(const std::vector<std::vector<PlacedEntry>>& runs, const Band& band,
                  std::vector<BrickEntry>& entries) const {
    std::vector<bool> seen(static_cast<size_t>(band.brick_count()), false);
    int64_t placed = 0;
    for (const std::vector<PlacedEntry>& run : runs) {
      for (const auto& [i, e] : run) {
        const int64_t local = i - band.first_brick;
        if (local < 0 || local >= band.brick_count() || seen[static_cast<size_t>(local)])
          throw IoError(output_ + ": ranks disagree on brick " + std::to_string(i));
        seen[static_cast<size_t>(local)] = true;
        entries[static_cast<size_t>(i)] = e;
        ++placed;
      }
    }
    if (placed != band.brick_count())
      throw IoError(output_ + ": the ranks' band " + std::to_string(band.scale) + " holds " + std::to_string(placed) +
                    " bricks, not " + std::to_string(band.brick_count()));
  }

  uint64_t input_bytes() const {
    const VolumeInfo& info = input_.info();
    return static_cast<uint64_t>(info.dims[0] * info.dims[1] * info.dims[2] * info.element_bytes);
  }

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
    header_.input_bytes = input_bytes();
    for (const Band& band : layout_.bands()) {
      const std::vector<BrickEntry> mine(entries.begin() + band.first_brick,
                                         entries.begin() + band.first_brick + band.brick_count());
      const std::vector<uint8_t> directory = encode_directory(mine);
      BandDirectory& d = header_.bands[static_cast<size_t>(band.scale)];
      d.offset = out_->size();
      d.bytes = directory.size();
      d.checksum = store_checksum(directory.data(), directory.size());
      out_->write(directory.data(), directory.size());
    }
    const auto header = encode_header(header_);
    out_->write_at(0, header.data(), header.size());
  }

  const BoxReader& quantized_or(const BoxReader& input, const ConvertCall& options) {
    if (options.quantize_bits == 0) return input;
    if (input.info().is_integer)
      throw OptionError("quantize", "applies to float data; integer data is stored losslessly as it is");
    quantized_ = std::make_unique<QuantizingReader>(input, options.quantize_bits, options.cancel);
    return *quantized_;
  }

  std::unique_ptr<QuantizingReader> quantized_;
  const BoxReader& input_;
  uint64_t input_held_bytes_ = 0;
  const ConvertCall options_;
  StoreLife life_;          // a distributed store is always kept
  StoreSections sections_;  // and holds all
  StoreLayout layout_;
  std::string output_;
  std::optional<AtomicFile> out_;  // alone, or rank 0
  std::string scratch_dir_;
  StoreHeader header_;
};

}  // namespace

ConvertStats convert_to_store(const BoxReader& input, const std::string& output, const ConvertCall& options,
                              StoreLife life, const StoreSections& sections) {
  if (options.zstd_level < 1 || options.zstd_level > 19) throw OptionError("zstd-level", "must be 1..19");
  if (options.memory_mb < 1) throw OptionError("memory-mb", "must be at least 1");
  if (options.quantize_bits != 0 && options.quantize_bits != 8 && options.quantize_bits != 16)
    throw OptionError("quantize", "must be 8 or 16");
  if (options.brick_bits < kMinBrickBits || options.brick_bits > kMaxBrickBits)
    throw OptionError("brick-bits", "must be " + std::to_string(kMinBrickBits) + ".." + std::to_string(kMaxBrickBits));
  validate_layout(input.info().dims, input.info().spacing, input.info().origin);
  // Distributed, the quantizer's pass over the input runs under settle_together: a rank whose
  // read fails stops every rank.
  std::optional<Converter> converter;
  if (options.distribution && (life != StoreLife::kept || sections != kAllSections))
    throw std::logic_error("convert_to_store: a distributed store is kept, with all its records' fields");
  auto make = [&] { converter.emplace(input, output, options, life, sections); };
  settle_together(options.distribution, make);
  return converter->run();
}

ConvertStats convert(const VolumeSpec& input, const std::string& output, const ConvertOptions& options,
                     const RunContext& run) {
  run.validate();
  const ThreadLimit threads(run.threads);
  std::unique_ptr<BoxReader> reader;
  auto open = [&] {
    check_outputs({{"INPUT", input.path}}, {{"OUTPUT", output}});
    // Scratch beside the output: on the file system the user chose for the store's size.
    const std::string scratch = std::filesystem::absolute(output).parent_path().string();
    reader = open_box_reader(input, scratch);
  };
  settle_together(run.distribution, open);  // every rank opens the input; one that cannot stops them all
  return convert_to_store(*reader, output, ConvertCall(options, run));
}

ConvertStats convert(const Volume& volume, const std::string& output, const ConvertOptions& options,
                     const RunContext& run) {
  run.validate();
  const ThreadLimit threads(run.threads);
  check_outputs({}, {{"OUTPUT", output}});
  validate_volume(volume);
  return convert_to_store(VolumeBoxReader(volume), output, ConvertCall(options, run));
}

}  // namespace isotope
