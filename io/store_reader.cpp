#include "io/store_reader.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <mutex>

#include "engine/parallel.h"
#include "io/io_error.h"
#include "io/store_brick.h"

namespace isotope {
namespace {

void pread_all(int fd, void* data, size_t bytes, uint64_t offset, const std::string& what) {
  auto* p = static_cast<char*>(data);
  while (bytes > 0) {
    const ssize_t n = ::pread(fd, p, bytes, static_cast<off_t>(offset));
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) throw IoError(what + ": read failed: " + std::strerror(errno));
    if (n == 0) throw IoError(what + ": file is truncated");
    p += n, bytes -= static_cast<size_t>(n), offset += static_cast<uint64_t>(n);
  }
}

}  // namespace

bool is_store_file(const std::string& path) {
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) return false;
  char magic[kStoreMagic.size()] = {};
  const bool ok = std::fread(magic, 1, sizeof magic, f) == sizeof magic &&
                  std::memcmp(magic, kStoreMagic.data(), sizeof magic) == 0;
  std::fclose(f);
  return ok;
}

StoreReader::StoreReader(const std::string& path) : path_(path) {
  fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd_ < 0) throw IoError(path + ": cannot open: " + std::strerror(errno));
  try {
    struct stat st {};
    if (::fstat(fd_, &st) != 0 || !S_ISREG(st.st_mode)) throw IoError(path + ": not a regular file");
    file_bytes_ = static_cast<uint64_t>(st.st_size);
    std::vector<uint8_t> head(kHeaderBytes);
    if (file_bytes_ < kHeaderBytes) throw IoError(path + ": not an isotope store (file is shorter than the header)");
    pread_all(fd_, head.data(), head.size(), 0, path);
    header_ = decode_header(head.data(), head.size(), path);
    layout_ = StoreLayout(header_.dims, header_.brick_bits);
    if (header_.directory_offset < kHeaderBytes || header_.directory_offset + header_.directory_bytes > file_bytes_)
      throw IoError(path + ": file is truncated (the directory lies beyond its end)");
    if (header_.directory_offset + header_.directory_bytes != file_bytes_)
      throw IoError(path + ": " + std::to_string(file_bytes_ - header_.directory_offset - header_.directory_bytes) +
                    " unexpected bytes after the directory");
    std::vector<uint8_t> dir(header_.directory_bytes);
    pread_all(fd_, dir.data(), dir.size(), header_.directory_offset, path);
    directory_ = decode_directory(dir.data(), dir.size(), header_, path);
  } catch (...) {
    ::close(fd_);
    throw;
  }
}

StoreReader::~StoreReader() { ::close(fd_); }

std::pair<int, Box3> StoreReader::locate_brick(int64_t index) const {
  for (const Band& b : layout_.bands())
    if (index >= b.first_brick && index < b.first_brick + b.brick_count()) {
      const int64_t i = index - b.first_brick;
      return {b.scale, {i % b.bricks[0], i / b.bricks[0] % b.bricks[1], i / (b.bricks[0] * b.bricks[1])}};
    }
  return {-1, {0, 0, 0}};
}

std::string StoreReader::describe_brick(int64_t index) const {
  const auto [band, b] = locate_brick(index);
  return path_ + ": brick " + std::to_string(index) + " (band " + std::to_string(band) + ", brick " +
         std::to_string(b[0]) + " " + std::to_string(b[1]) + " " + std::to_string(b[2]) + ")";
}

void StoreReader::prefetch_after(int64_t index, int bricks) const {
  const BrickEntry& e = directory_.at(static_cast<size_t>(index));
  const uint64_t begin = e.offset + e.compressed_bytes;
  const uint64_t end = std::min(header_.directory_offset, begin + static_cast<uint64_t>(bricks) * e.compressed_bytes);
  if (end > begin) ::posix_fadvise(fd_, static_cast<off_t>(begin), static_cast<off_t>(end - begin), POSIX_FADV_WILLNEED);
}

std::vector<uint8_t> StoreReader::read_compressed(int64_t index) const {
  const BrickEntry& e = directory_.at(static_cast<size_t>(index));
  std::vector<uint8_t> bytes(e.compressed_bytes);
  pread_all(fd_, bytes.data(), bytes.size(), e.offset, describe_brick(index));
  return bytes;
}

std::vector<float> StoreReader::read_stored_values(int64_t index) const {
  const BrickEntry& e = directory_.at(static_cast<size_t>(index));
  const std::vector<uint8_t> bytes = read_compressed(index);
  if (locate_brick(index).first == 0) {
    const int64_t w = halo_width(layout_);
    std::vector<float> halo(static_cast<size_t>(w * w * w));
    std::vector<Record> none;
    decode_brick(bytes.data(), e, halo, none, describe_brick(index));
    return halo;
  }
  std::vector<float> values(static_cast<size_t>(layout_.brick_nodes()));
  std::vector<Record> records(static_cast<size_t>(layout_.brick_records()));
  decode_brick(bytes.data(), e, values, records, describe_brick(index));
  return values;
}

BrickContents StoreReader::read_brick(int64_t index) const {
  const auto [j, b] = locate_brick(index);
  if (j == 0) {  // values with a halo; the records are rebuilt from them (io/store_brick.h)
    // The tile's arrays are the same size for every brick: each thread keeps one set, rather
    // than faulting in fresh pages for every brick a paged extraction decodes.
    thread_local BandTile::Buffers spare;
    BandTile tile = tile_for_brick(layout_, 0, b, std::move(spare));
    fill_from_halo(tile, read_stored_values(index));
    CriticalCounts counts = {{0, 0, 0}, {0, 0, 0}};
    tile.build(counts);
    BrickContents c = contents_of(tile, tile.core_lo(), header_.quantize_bits != 0 ? kQuantizationError : 0.0f);
    spare = tile.release();
    return c;
  }
  const BrickEntry& e = directory_.at(static_cast<size_t>(index));
  const std::vector<uint8_t> bytes = read_compressed(index);
  BrickContents c;
  c.values.resize(static_cast<size_t>(layout_.brick_nodes()));
  c.records.resize(static_cast<size_t>(layout_.brick_records()));
  decode_brick(bytes.data(), e, c.values, c.records, describe_brick(index));
  return c;
}

MultiresVolume StoreReader::load(const ProgressCallback& progress) const {
  MultiresVolume mv = MultiresVolume::allocate(header_.dims, header_.spacing, header_.origin);
  PreprocessStats stats;
  for (int t = 0; t < 3; ++t) {
    stats.critical_paper[t] = header_.critical_paper[t];
    stats.critical_exact[t] = header_.critical_exact[t];
  }
  mv.set_stats(stats);
  mv.set_value_map(header_.value_offset, header_.value_scale);
  const int bits = layout_.brick_bits();
  const int64_t t = layout_.brick_width();
  const auto& dims = header_.dims;
  ProgressReporter reporter(progress, layout_.brick_count());
  // Values from band 0 (it holds every data node); records of scale j from band j.
  parallel_for(int64_t{0}, layout_.brick_count(), [&](int64_t index) {
    const auto [j, b] = locate_brick(index);
    const Band& band = layout_.band(j);
    const BrickContents c = read_brick(index);  // also the corners' brick: a corrupt brick is never ignored
    if (j == layout_.lattice().k) return reporter.advance(1);  // their values are in band 0 too
    for (int64_t z = 0; z < t && b[2] * t + z < band.nodes[2]; ++z)
      for (int64_t y = 0; y < t && b[1] * t + y < band.nodes[1]; ++y)
        for (int64_t x = 0; x < t && b[0] * t + x < band.nodes[0]; ++x) {
          const int64_t gx = b[0] * t + x, gy = b[1] * t + y, gz = b[2] * t + z;
          const uint32_t m = brick_morton(x, y, z, bits);
          if (j == 0 && gx < dims[0] && gy < dims[1] && gz < dims[2]) mv.set_value(gx, gy, gz, c.values[m]);
          if ((m & 7) != 0) mv.set_record({gx << j, gy << j, gz << j}, c.records[brick_record_index(m)]);
        }
    reporter.advance(1);
  });
  return mv;
}

}  // namespace isotope

namespace isotope {
namespace {

bool same_bits(const void* a, const void* b, size_t n) { return std::memcmp(a, b, n) == 0; }

// The format's invariants inside one decoded brick; returns what is wrong, or "".
std::string check_brick(const StoreReader& store, int64_t index, const BrickContents& c) {
  const StoreLayout& layout = store.layout();
  const auto [j, b] = store.locate_brick(index);
  const Band& band = layout.band(j);
  const int64_t t = layout.brick_width();
  const BrickSummary s = summarize_brick(c);
  if (!same_bits(&s, &store.directory()[static_cast<size_t>(index)].summary, sizeof s))
    return "directory summary does not match the brick";
  for (int64_t z = 0; z < t; ++z)
    for (int64_t y = 0; y < t; ++y)
      for (int64_t x = 0; x < t; ++x) {
        const uint32_t m = brick_morton(x, y, z, layout.brick_bits());
        const bool in_grid = b[0] * t + x < band.nodes[0] && b[1] * t + y < band.nodes[1] && b[2] * t + z < band.nodes[2];
        const float v = c.values[m];
        const std::string node = "node " + std::to_string(b[0] * t + x) + " " + std::to_string(b[1] * t + y) + " " +
                                 std::to_string(b[2] * t + z) + ": ";
        if (!in_grid && v != 0.0f) return node + "a value outside the grid is not zero";
        if (in_grid && !std::isfinite(v)) return node + "value is not finite";
        if ((m & 7) == 0) continue;
        const Record& r = c.records[brick_record_index(m)];
        if (!in_grid || j == layout.lattice().k) {
          if (!same_bits(&r, &kAbsentRecord, sizeof r)) return node + "a record outside the grid is not zero";
          continue;
        }
        if (!(r.bounds.lo <= v && v <= r.bounds.hi)) return node + "value outside its record's range";
        if (!(r.bounds.error_surplus >= 0) || !(r.bounds.error_bound >= r.bounds.error_surplus))
          return node + "error indicators are negative, NaN, or bound < surplus";
        if (std::isnan(r.topology.exact_lo) || std::isnan(r.topology.exact_hi) || std::isnan(r.topology.paper_lo) ||
            std::isnan(r.topology.paper_hi) || !(r.topology.weight[0] >= 0) || !(r.topology.weight[1] >= 0) ||
            !(r.topology.weight[2] >= 0))
          return node + "critical intervals or weight are NaN or negative";
      }
  return {};
}

// Band 0: the halos of neighbouring bricks overlap, and must agree there (they are copies of the
// same nodes). Compared with the brick's seven neighbours above it in x, y and/or z.
std::string check_halos(const StoreReader& store, int64_t index) {
  const StoreLayout& layout = store.layout();
  const auto [j, b] = store.locate_brick(index);
  const Band& band = layout.band(0);
  const int64_t t = layout.brick_width();
  const std::vector<float> mine = store.read_stored_values(index);
  for (int d = 1; d < 8; ++d) {
    const Box3 nb{b[0] + (d & 1), b[1] + (d >> 1 & 1), b[2] + (d >> 2)};
    if (nb[0] >= band.bricks[0] || nb[1] >= band.bricks[1] || nb[2] >= band.bricks[2]) continue;
    const int64_t other_index = layout.brick_index(0, nb);
    const std::vector<float> other = store.read_stored_values(other_index);
    // The overlap of the boxes [b t - 2, b t + t + 2) and [nb t - 2, ...), per axis.
    Box3 lo, hi;
    for (int a = 0; a < 3; ++a) lo[a] = nb[a] * t - 2, hi[a] = b[a] * t + t + 2;
    for (int64_t z = lo[2]; z < hi[2]; ++z)
      for (int64_t y = lo[1]; y < hi[1]; ++y)
        for (int64_t x = lo[0]; x < hi[0]; ++x) {
          auto at = [&](const Box3& brick) {
            return static_cast<size_t>(halo_index(layout, {brick[0] * t, brick[1] * t, brick[2] * t}, {x, y, z}));
          };
          if (!same_bits(&mine[at(b)], &other[at(nb)], sizeof(float)))
            return "its halo disagrees with brick " + std::to_string(other_index) + " at node " + std::to_string(x) +
                   " " + std::to_string(y) + " " + std::to_string(z);
        }
  }
  return {};
}

// Bands j >= 1 repeat values of band j-1: node g holds band j-1's value at 2g (clamped to its grid).
std::string check_values_against_finer_band(const StoreReader& store, int64_t index) {
  const StoreLayout& layout = store.layout();
  const auto [j, b] = store.locate_brick(index);
  const Band &band = layout.band(j), &finer = layout.band(j - 1);
  const int bits = layout.brick_bits();
  const int64_t t = layout.brick_width();
  const std::vector<float> mine = store.read_stored_values(index);
  std::vector<std::pair<int64_t, std::vector<float>>> cache;  // the few finer bricks below this one
  auto finer_value = [&](const Box3& q) {
    const Box3 fb{q[0] >> bits, q[1] >> bits, q[2] >> bits};
    const int64_t fi = layout.brick_index(j - 1, fb);
    auto it = std::find_if(cache.begin(), cache.end(), [&](const auto& c) { return c.first == fi; });
    if (it == cache.end()) it = cache.insert(cache.end(), {fi, store.read_stored_values(fi)});
    const Box3 l{q[0] - fb[0] * t, q[1] - fb[1] * t, q[2] - fb[2] * t};
    const auto k = j - 1 == 0 ? static_cast<size_t>(halo_index(layout, {0, 0, 0}, l))
                              : static_cast<size_t>(brick_morton(l[0], l[1], l[2], bits));
    return it->second[k];
  };
  for (int64_t z = 0; z < t && b[2] * t + z < band.nodes[2]; ++z)
    for (int64_t y = 0; y < t && b[1] * t + y < band.nodes[1]; ++y)
      for (int64_t x = 0; x < t && b[0] * t + x < band.nodes[0]; ++x) {
        const Box3 g{b[0] * t + x, b[1] * t + y, b[2] * t + z};
        Box3 q;
        for (int a = 0; a < 3; ++a) q[a] = std::min(2 * g[a], finer.nodes[a] - 1);
        const float expected = finer_value(q);
        if (!same_bits(&mine[brick_morton(x, y, z, bits)], &expected, sizeof(float)))
          return "value at node " + std::to_string(g[0]) + " " + std::to_string(g[1]) + " " + std::to_string(g[2]) +
                 " differs from band " + std::to_string(j - 1);
      }
  return {};
}

}  // namespace

VerifyStats verify_store(const std::string& path, const ProgressCallback& progress) {
  const StoreReader store(path);
  const auto& dir = store.directory();
  // The bricks tile the space between the header and the directory, without gaps or overlaps.
  std::vector<int64_t> order(dir.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = static_cast<int64_t>(i);
  std::sort(order.begin(), order.end(), [&](int64_t a, int64_t b) { return dir[static_cast<size_t>(a)].offset < dir[static_cast<size_t>(b)].offset; });
  uint64_t at = kHeaderBytes;
  for (int64_t i : order) {
    const BrickEntry& e = dir[static_cast<size_t>(i)];
    if (e.offset != at) throw IoError(store.describe_brick(i) + ": directory offset overlaps or leaves a gap");
    at += e.compressed_bytes;
  }
  if (at != store.header().directory_offset) throw IoError(path + ": bricks do not end where the directory starts");

  std::vector<std::string> problems(dir.size());
  // The brick reported is the first in directory order that has a problem, whatever the threads
  // did: bricks after the first problem found so far are skipped, those before it still checked.
  std::atomic<int64_t> first_problem{std::numeric_limits<int64_t>::max()};
  std::mutex range_mutex;
  float lo = INFINITY, hi = -INFINITY;
  ProgressReporter reporter(progress, static_cast<int64_t>(dir.size()));
  parallel_for(int64_t{0}, static_cast<int64_t>(dir.size()), [&](int64_t i) {
    if (i > first_problem.load(std::memory_order_relaxed)) return;
    try {
      const BrickContents c = store.read_brick(i);
      std::string problem = check_brick(store, i, c);
      if (problem.empty())
        problem = store.locate_brick(i).first == 0 ? check_halos(store, i) : check_values_against_finer_band(store, i);
      if (!problem.empty()) throw IoError(store.describe_brick(i) + ": " + problem);
      if (store.locate_brick(i).first == 0) {
        std::lock_guard<std::mutex> lock(range_mutex);
        lo = std::min(lo, dir[static_cast<size_t>(i)].summary.lo);
        hi = std::max(hi, dir[static_cast<size_t>(i)].summary.hi);
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
  stats.bricks = static_cast<int64_t>(dir.size());
  for (const BrickEntry& e : dir) stats.compressed_bytes += e.compressed_bytes, stats.raw_bytes += e.raw_bytes;
  return stats;
}

}  // namespace isotope
