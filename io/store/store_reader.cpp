#include "io/store/store_reader.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <sys/uio.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <limits>

#include "engine/core/parallel.h"
#include "io/file/checked_size.h"
#include "io/file/input_file.h"
#include "io/file/positioned_io.h"
#include "io/store/held_words.h"
#include "isotope/error.h"

namespace isotope {
namespace {

void read_span(int fd, void* data, size_t bytes, uint64_t offset, const std::string& what) {
  const PreadOutcome r = pread_all(fd, data, bytes, offset);
  if (r.error != 0) throw IoError(what + ": read failed: " + std::strerror(r.error));
  if (r.ended_early(bytes)) throw IoError(what + ": file is truncated");
}

// Runs of consecutive sections that `which` names, as (first, end) section indices.
template <class F>
void for_each_run(const StoreSections& which, F f) {
  for (int s = 0; s < kSections;) {
    if (!which[static_cast<size_t>(s)]) {
      ++s;
      continue;
    }
    int e = s;
    while (e < kSections && which[static_cast<size_t>(e)]) ++e;
    f(s, e);
    s = e;
  }
}

}  // namespace

bool is_store_file(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) return false;  // never open a FIFO (the input policy)
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) return false;
  char magic[kStoreMagic.size()] = {};
  const bool ok = std::fread(magic, 1, sizeof magic, f) == sizeof magic &&
                  std::memcmp(magic, kStoreMagic.data(), sizeof magic) == 0;
  std::fclose(f);
  return ok;
}

StoreReader::StoreReader(const std::string& path) : path_(path) {
  require_regular_file(path, path, "an isotope store");
  fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd_ < 0) throw IoError(path + ": cannot open: " + std::strerror(errno));
  // The reader asks for what it reads ahead (advise_window: a brick's 64 KB window, and the hints
  // ahead of the traversal), so the kernel's own read-ahead is turned off: on a device whose
  // read-ahead is 8 MB, reading the header and the directories can pull in megabytes of bricks no
  // extraction asked for, and whether a read finds its brick there becomes a race.
  ::posix_fadvise(fd_, 0, 0, POSIX_FADV_RANDOM);
  try {
    struct stat st {};
    if (::fstat(fd_, &st) != 0 || !S_ISREG(st.st_mode)) throw IoError(path + ": not a regular file");
    file_bytes_ = static_cast<uint64_t>(st.st_size);
    if (file_bytes_ < kHeaderBytes) throw IoError(path + ": not an isotope store (file is shorter than the header)");
    std::vector<uint8_t> head(kHeaderBytes);
    read_span(fd_, head.data(), head.size(), 0, path);
    header_ = decode_header(head.data(), head.size(), path);
    layout_ = StoreLayout(header_.dims, header_.brick_bits);
    // The directories follow the bricks, band after band, and end the file.
    area_end_ = header_.bands[0].offset;
    uint64_t at = area_end_;
    for (int j = 0; j <= header_.lattice_k; ++j) {
      const BandDirectory& d = header_.bands[static_cast<size_t>(j)];
      if (d.offset != at || !range_within(d.offset, d.bytes, file_bytes_))
        throw IoError(path + ": file is truncated or its directories overlap (band " + std::to_string(j) + ")");
      at = d.offset + d.bytes;
    }
    if (area_end_ < kHeaderBytes) throw IoError(path + ": the directories overlap the header");
    if (at != file_bytes_)
      throw IoError(path + ": " + std::to_string(file_bytes_ - at) + " unexpected bytes after the directories");
    directories_ = std::make_unique<LazyDirectory[]>(static_cast<size_t>(header_.lattice_k + 1));
  } catch (...) {
    ::close(fd_);
    throw;
  }
}

StoreReader::~StoreReader() { ::close(fd_); }

const StoreReader::Directory& StoreReader::band_directory(int band) const {
  LazyDirectory& d = directories_[static_cast<size_t>(band)];
  const std::lock_guard<std::mutex> lock(d.mutex);
  if (!d.entries) {
    const BandDirectory& where = header_.bands[static_cast<size_t>(band)];
    // Faulted in at once before the zero-fill and the read write it: a large band's directory is
    // megabytes of fresh memory (docs/METHOD.md, "Fresh memory")
    auto entries = std::make_shared<Directory>();
    detail::resize_prefaulted(*entries, static_cast<size_t>(layout_.band(band).brick_count()));
    if (where.bytes != entries->size() * kEntryBytes) throw IoError(path_ + ": directory is truncated");
    read_span(fd_, entries->data(), where.bytes, where.offset, path_);
    check_directory(*entries, layout_.band(band).bricks, where, area_end_, path_);
    d.entries = std::move(entries);
  }
  return *d.entries;
}

const BrickEntry& StoreReader::entry(int64_t index) const {
  const auto [band, b] = locate_brick(index);
  if (band < 0) throw IoError(path_ + ": no brick " + std::to_string(index));
  return band_directory(band)[static_cast<size_t>(index - layout_.band(band).first_brick)];
}

std::pair<int, Box3> StoreReader::locate_brick(int64_t index) const {
  for (const Band& b : layout_.bands())
    if (index >= b.first_brick && index < b.first_brick + b.brick_count())
      return {b.scale, StoreLayout::brick_of(b, index)};
  return {-1, {0, 0, 0}};
}

std::string StoreReader::describe_brick(int64_t index) const {
  const auto [band, b] = locate_brick(index);
  return path_ + ": brick " + std::to_string(index) + " (band " + std::to_string(band) + ", brick " +
         std::to_string(b[0]) + " " + std::to_string(b[1]) + " " + std::to_string(b[2]) + ")";
}

void StoreReader::advise_window(uint64_t begin, uint64_t stop) const {
  const uint64_t from = begin & ~(kReadWindow - 1);
  const uint64_t to = std::min(area_end_, (stop + kReadWindow - 1) & ~(kReadWindow - 1));
  if (to > from) ::posix_fadvise(fd_, static_cast<off_t>(from), static_cast<off_t>(to - from), POSIX_FADV_WILLNEED);
}

void StoreReader::read_range(uint8_t* data, uint64_t begin, uint64_t stop, int64_t index) const {
  const size_t bytes = stop - begin;
  iovec v{data, bytes};
  // RWF_NOWAIT reads only what the page cache holds: a warm store pays one call, as with pread.
  // Any shortfall (or a kernel or file system without it) goes the slow way, whole.
  if (::preadv2(fd_, &v, 1, static_cast<off_t>(begin), RWF_NOWAIT) == static_cast<ssize_t>(bytes)) return;
  waits_.fetch_add(1, std::memory_order_relaxed);
  advise_window(begin, stop);
  read_span(fd_, data, bytes, begin, describe_brick(index));
}

void StoreReader::prefetch(int64_t index, const StoreSections& which) const {
  if (!hints_pay()) return;
  const BrickEntry& e = entry(index);
  for_each_run(which, [&](int s, int end) {
    const uint64_t begin = e.section_offset(static_cast<Section>(s));
    const uint64_t stop = e.section_offset(static_cast<Section>(end));
    if (stop > begin) {
      advise_window(begin, stop);
      hints_.fetch_add(1, std::memory_order_relaxed);
    }
  });
}

uint64_t StoreReader::read_brick(int64_t index, const StoreSections& which, const BrickView& out, float* values,
                                 const NarrowBrick* narrow) const {
  const BrickEntry& e = entry(index);
  const int band = locate_brick(index).first;
  uint64_t read = 0;
  thread_local std::vector<uint8_t> bytes;
  for_each_run(which, [&](int s, int end) {
    const uint64_t begin = e.section_offset(static_cast<Section>(s));
    const uint64_t stop = e.section_offset(static_cast<Section>(end));
    bytes.resize(stop - begin);
    if (!bytes.empty()) read_range(bytes.data(), begin, stop, index);
    read += bytes.size();
    uint64_t at = 0;
    for (int k = s; k < end; ++k) {
      const uint32_t size = e.bytes[static_cast<size_t>(k)];
      decode_section(layout_, band, static_cast<Section>(k), bytes.data() + at, size, out, values,
                     describe_brick(index), narrow);
      at += size;
    }
  });
  return read;
}

namespace {

struct FullBrick {
  explicit FullBrick(int64_t n)
      : values(static_cast<size_t>(n)),
        bounds(static_cast<size_t>(n)),
        surplus(static_cast<size_t>(n)),
        exact(static_cast<size_t>(n)),
        paper(static_cast<size_t>(n)),
        weights(static_cast<size_t>(n)) {}
  BrickView view() {
    return {values.data(), bounds.data(), surplus.data(), exact.data(), paper.data(), weights.data()};
  }
  std::vector<float> values;
  std::vector<uint64_t> bounds;
  std::vector<uint16_t> surplus;
  std::vector<uint32_t> exact, paper;
  std::vector<uint64_t> weights;
};

// The format's invariants inside one decoded brick; returns what is wrong, or "".
std::string check_brick(const StoreReader& store, int64_t index, FullBrick& brick) {
  const StoreLayout& layout = store.layout();
  const auto [j, b] = store.locate_brick(index);
  const Band& band = layout.band(j);
  const int64_t t = layout.brick_width();
  const bool records = stores_records(layout, j);
  for (int64_t z = 0; z < t; ++z)
    for (int64_t y = 0; y < t; ++y)
      for (int64_t x = 0; x < t; ++x) {
        const uint32_t m = brick_morton(x, y, z, layout.brick_bits());
        const bool in_grid =
            b[0] * t + x < band.nodes[0] && b[1] * t + y < band.nodes[1] && b[2] * t + z < band.nodes[2];
        const float v = brick.values[m];
        // Named only when something is wrong: a string per node made verify spend most of its time
        // formatting names nobody read.
        const auto node =
            [&, g = Box3{b[0] * t + x, b[1] * t + y, b[2] * t + z}] {  // a copy: clang 14 captures no binding
              return "node " + std::to_string(g[0]) + " " + std::to_string(g[1]) + " " + std::to_string(g[2]) + ": ";
            };
        if (!in_grid && v != 0.0f) return node() + "a value outside the grid is not zero";
        if (in_grid && !std::isfinite(v)) return node() + "value is not finite";
        if (!records || (m & 7) == 0) continue;
        const bool zero = brick.bounds[m] == 0 && brick.surplus[m] == 0 && brick.exact[m] == 0 && brick.paper[m] == 0 &&
                          brick.weights[m] == 0;
        if (!in_grid) {
          if (!zero) return node() + "a record outside the grid is not zero";
          continue;
        }
        const DiamondBounds r{bf16_to_float(bounds_of(brick.bounds[m]).lo),
                              bf16_to_float(bounds_of(brick.bounds[m]).hi), bounds_of(brick.bounds[m]).bound,
                              bf16_to_float(brick.surplus[m])};
        const DiamondTopology top = topology_of(brick.exact[m], brick.paper[m], brick.weights[m]);
        if (!(r.lo <= v && v <= r.hi)) return node() + "value outside its record's range";
        if (!(r.error_surplus >= 0) || !(r.error_bound >= 0)) return node() + "error indicators are negative or NaN";
        if (std::isnan(top.exact_lo) || std::isnan(top.exact_hi) || std::isnan(top.paper_lo) ||
            std::isnan(top.paper_hi) || !(top.weight[0] >= 0) || !(top.weight[1] >= 0) || !(top.weight[2] >= 0))
          return node() + "critical intervals or weights are NaN or negative";
      }
  return {};
}

// What the extraction's cache checks of every brick it reads (held_value_bytes, narrow_bounds): values
// within the width the header promises, and beside values of one byte, records narrow words hold.
std::string check_held_widths(const StoreReader& store, int64_t index, const FullBrick& brick) {
  const int bytes = held_value_bytes(store.header());
  if (bytes == 4) return {};
  if (fewest_bytes(brick.values) > bytes) return value_not_held(store.header());
  thread_local std::vector<uint32_t> narrow;
  narrow.resize(brick.bounds.size());
  const bool records = stores_records(store.layout(), store.locate_brick(index).first);
  if (held_bounds_bytes(bytes) == 4 && records &&
      !narrow_bounds(brick.bounds.data(), brick.bounds.size(), narrow.data()))
    return kRecordNotHeld;
  return {};
}

// Bands j >= 1 repeat values of band j-1: node g holds band j-1's value at 2g (clamped to its grid).
std::string check_values_against_finer_band(const StoreReader& store, int64_t index, const FullBrick& brick) {
  const StoreLayout& layout = store.layout();
  const auto [band_j, b] = store.locate_brick(index);
  const int j = band_j;  // a copy: lambdas cannot capture a structured binding before C++20 in clang 14
  const Band &band = layout.band(j), &finer = layout.band(j - 1);
  const int bits = layout.brick_bits();
  const int64_t t = layout.brick_width();
  // The few finer bricks below this one (at most eight), the first `used` of the thread's: their
  // arrays are kept from one brick to the next. Made fresh for each brick, zero-filled, they cost
  // most of a verify's time in page faults (embryo: 131 k faults, 1.8 s of processor time;
  // docs/METHOD.md, "Fresh memory").
  thread_local std::vector<std::pair<int64_t, std::unique_ptr<FullBrick>>> cache;
  size_t used = 0;
  auto finer_value = [&](const Box3& q) {
    const Box3 fb{q[0] >> bits, q[1] >> bits, q[2] >> bits};
    const int64_t fi = layout.brick_index(j - 1, fb);
    const auto mine = cache.begin() + static_cast<std::ptrdiff_t>(used);
    auto it = std::find_if(cache.begin(), mine, [&](const auto& c) { return c.first == fi; });
    if (it == mine) {
      if (used == cache.size()) cache.emplace_back(-1, nullptr);
      auto& [held, finer_brick] = cache[used];
      if (!finer_brick || static_cast<int64_t>(finer_brick->values.size()) != layout.brick_nodes())
        finer_brick = std::make_unique<FullBrick>(layout.brick_nodes());
      held = -1;  // until read: a read that throws leaves no brick under its index
      store.read_brick(fi, {true, false, false, false}, finer_brick->view(), finer_brick->values.data());
      held = fi;
      it = cache.begin() + static_cast<std::ptrdiff_t>(used++);
    }
    return it->second->values[brick_morton(q[0] - fb[0] * t, q[1] - fb[1] * t, q[2] - fb[2] * t, bits)];
  };
  for (int64_t z = 0; z < t && b[2] * t + z < band.nodes[2]; ++z)
    for (int64_t y = 0; y < t && b[1] * t + y < band.nodes[1]; ++y)
      for (int64_t x = 0; x < t && b[0] * t + x < band.nodes[0]; ++x) {
        const Box3 g{b[0] * t + x, b[1] * t + y, b[2] * t + z};
        Box3 q;
        for (int a = 0; a < 3; ++a) q[a] = std::min(2 * g[a], finer.nodes[a] - 1);
        const float expected = finer_value(q), mine = brick.values[brick_morton(x, y, z, bits)];
        if (std::memcmp(&mine, &expected, sizeof(float)) != 0)
          return "value at node " + std::to_string(g[0]) + " " + std::to_string(g[1]) + " " + std::to_string(g[2]) +
                 " differs from band " + std::to_string(j - 1);
      }
  return {};
}

}  // namespace

VerifyStats verify_store(const std::string& path, const ProgressCallback& progress) {
  const StoreReader store(path);
  const StoreLayout& layout = store.layout();
  const auto bricks = static_cast<size_t>(layout.brick_count());
  // The bricks tile the space between the header and the directories, without gaps or overlaps.
  std::vector<int64_t> order(bricks);
  for (size_t i = 0; i < bricks; ++i) order[i] = static_cast<int64_t>(i);
  std::sort(order.begin(), order.end(),
            [&](int64_t a, int64_t b) { return store.entry(a).offset < store.entry(b).offset; });
  uint64_t at = kHeaderBytes;
  for (int64_t i : order) {
    const BrickEntry& e = store.entry(i);
    if (e.offset != at) throw IoError(store.describe_brick(i) + ": directory offset overlaps or leaves a gap");
    at += e.total();
  }
  if (at != store.brick_area_end()) throw IoError(path + ": bricks do not end where the directories start");

  std::vector<std::string> problems(bricks);
  // The brick reported is the first in directory order that has a problem, whatever the threads
  // did: bricks after the first problem found so far are skipped, those before it still checked.
  std::atomic<int64_t> first_problem{std::numeric_limits<int64_t>::max()};
  std::mutex range_mutex;
  float lo = INFINITY, hi = -INFINITY;
  ProgressReporter reporter(progress, static_cast<int64_t>(bricks));
  parallel_for(int64_t{0}, static_cast<int64_t>(bricks), [&](int64_t i) {
    if (i > first_problem.load(std::memory_order_relaxed)) return;
    try {
      thread_local std::unique_ptr<FullBrick> brick;
      if (!brick || static_cast<int64_t>(brick->values.size()) != layout.brick_nodes())
        brick = std::make_unique<FullBrick>(layout.brick_nodes());
      std::fill(brick->bounds.begin(), brick->bounds.end(), 0);
      std::fill(brick->surplus.begin(), brick->surplus.end(), 0);
      std::fill(brick->exact.begin(), brick->exact.end(), 0);
      std::fill(brick->paper.begin(), brick->paper.end(), 0);
      std::fill(brick->weights.begin(), brick->weights.end(), 0);
      store.read_brick(i, kAllSections, brick->view(), brick->values.data());
      const auto [j, b] = store.locate_brick(i);
      std::string problem = check_brick(store, i, *brick);
      if (problem.empty()) problem = check_held_widths(store, i, *brick);
      if (problem.empty() && j > 0) problem = check_values_against_finer_band(store, i, *brick);
      if (!problem.empty()) throw IoError(store.describe_brick(i) + ": " + problem);
      if (j == 0) {  // the data's range, from its nodes in the data box
        const int64_t t = layout.brick_width();
        float blo = INFINITY, bhi = -INFINITY;
        for (uint32_t m = 0; m < static_cast<uint32_t>(layout.brick_nodes()); ++m) {
          const Box3 g{b[0] * t + compact_bits_3(m), b[1] * t + compact_bits_3(m >> 1),
                       b[2] * t + compact_bits_3(m >> 2)};
          if (g[0] >= layout.dims()[0] || g[1] >= layout.dims()[1] || g[2] >= layout.dims()[2]) continue;
          blo = std::min(blo, brick->values[m]);
          bhi = std::max(bhi, brick->values[m]);
        }
        std::lock_guard<std::mutex> lock(range_mutex);
        lo = std::min(lo, blo);
        hi = std::max(hi, bhi);
      }
    } catch (const IoError& e) {
      problems[static_cast<size_t>(i)] = e.what();
      int64_t seen = first_problem.load();
      while (i < seen && !first_problem.compare_exchange_weak(seen, i)) {
      }
    }
    reporter.advance(1);
  });
  for (const std::string& p : problems)
    if (!p.empty()) throw IoError(p);
  const StoreHeader& h = store.header();
  const bool range_ok = h.quantize_bits == 0
                            ? static_cast<double>(lo) == h.value_min && static_cast<double>(hi) == h.value_max
                            : lo >= 0 && hi <= static_cast<float>((1 << h.quantize_bits) - 1);
  if (!range_ok) throw IoError(path + ": the header's value range does not match the bricks");
  VerifyStats stats;
  stats.bricks = static_cast<int64_t>(bricks);
  stats.compressed_bytes = store.brick_area_end() - kHeaderBytes;
  return stats;
}

}  // namespace isotope
