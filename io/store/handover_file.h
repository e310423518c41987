#pragma once
// A band's hand-over (BandHandover) in a file, for volumes whose hand-over does
// not fit the convert's budget: in scratch files beside the output, or in one named file that
// every process of a distributed convert writes its tiles' parts into.
#include <algorithm>
#include <cstdint>
#include <string>
#include <vector>

#include "engine/hierarchy/banded_build.h"
#include "io/file/scratch_file.h"
#include "io/file/shared_file.h"

namespace isotope {

// A band's hand-over in a file, laid out in cubes of kHandoverBlock^3 entries, each in a slot of
// that many (the grid's last cubes along an axis are thinner), x fastest within a cube and cubes
// x fastest in the grid. A tile writes its part, whole cubes, in a call a cube, where a row-major
// file took a call a row of 16-64 entries, each into pages other tiles wrote too (at 2048^3 the
// kernel took 20% of the convert's time that way, 14% in cubes: docs/FORMAT.md); a reader takes
// the planes it needs of each cube it crosses in a call, rows and columns it does not need with
// them.
class BlockedEntries {
 public:
  explicit BlockedEntries(const Box3& nodes) : nodes_(nodes) {
    for (int a = 0; a < 3; ++a) cubes_[a] = (nodes[a] + kB - 1) / kB;
  }
  uint64_t slots() const { return static_cast<uint64_t>(cubes_[0] * cubes_[1] * cubes_[2]) * kB * kB * kB; }

  // Entries lo .. hi - 1 from memory (row, plane: as BandHandover says) at byte `base` of FILE.
  template <class T, class File>
  void write(const File& file, uint64_t base, const Box3& lo, const Box3& hi, const T* from, int64_t row,
             int64_t plane) const {
    for_each_cube(lo, hi, [&](const Box3& c0, const Box3& c1, const Box3& i0, const Box3& i1, uint64_t slot) {
      // The planes of the cube in the box, in a call when the box holds their whole rows (else
      // one a row: a box cut off a cube's grid, as tiles of a few nodes make).
      const int64_t cx = c1[0] - c0[0], cy = c1[1] - c0[1];
      const bool whole = i0[0] == c0[0] && i1[0] == c1[0] && i0[1] == c0[1] && i1[1] == c1[1];
      thread_local std::vector<T> staged;
      if (whole) staged.resize(static_cast<size_t>((i1[2] - i0[2]) * cx * cy));
      for (int64_t z = i0[2]; z < i1[2]; ++z)
        for (int64_t y = i0[1]; y < i1[1]; ++y) {
          const T* src = from + (z - lo[2]) * plane + (y - lo[1]) * row + (i0[0] - lo[0]);
          const int64_t in_cube = ((z - c0[2]) * cy + (y - c0[1])) * cx + (i0[0] - c0[0]);
          if (whole)
            std::copy_n(src, cx, staged.data() + ((z - i0[2]) * cy + (y - c0[1])) * cx);
          else
            file.write(src, static_cast<size_t>(i1[0] - i0[0]) * sizeof(T), at(base, slot, in_cube, sizeof(T)));
        }
      if (whole)
        file.write(staged.data(), staged.size() * sizeof(T), at(base, slot, (i0[2] - c0[2]) * cx * cy, sizeof(T)));
    });
  }

  template <class T, class File>
  void read(const File& file, uint64_t base, const Box3& lo, const Box3& hi, T* to, int64_t row, int64_t plane) const {
    for_each_cube(lo, hi, [&](const Box3& c0, const Box3& c1, const Box3& i0, const Box3& i1, uint64_t slot) {
      const int64_t cx = c1[0] - c0[0], cy = c1[1] - c0[1];
      thread_local std::vector<T> staged;
      staged.resize(static_cast<size_t>((i1[2] - i0[2]) * cx * cy));
      file.read(staged.data(), staged.size() * sizeof(T), at(base, slot, (i0[2] - c0[2]) * cx * cy, sizeof(T)));
      for (int64_t z = i0[2]; z < i1[2]; ++z)
        for (int64_t y = i0[1]; y < i1[1]; ++y)
          std::copy_n(staged.data() + ((z - i0[2]) * cy + (y - c0[1])) * cx + (i0[0] - c0[0]), i1[0] - i0[0],
                      to + (z - lo[2]) * plane + (y - lo[1]) * row + (i0[0] - lo[0]));
    });
  }

 private:
  static constexpr int64_t kB = kHandoverBlock;
  static uint64_t at(uint64_t base, uint64_t slot, int64_t entry, size_t size) {
    return base + (slot * kB * kB * kB + static_cast<uint64_t>(entry)) * size;
  }
  // f(cube lo, cube hi, the box's part lo, hi, slot) for each cube the box lo .. hi - 1 crosses.
  template <class F>
  void for_each_cube(const Box3& lo, const Box3& hi, const F& f) const {
    if (hi[0] <= lo[0] || hi[1] <= lo[1] || hi[2] <= lo[2]) return;
    for (int64_t bz = lo[2] / kB; bz <= (hi[2] - 1) / kB; ++bz)
      for (int64_t by = lo[1] / kB; by <= (hi[1] - 1) / kB; ++by)
        for (int64_t bx = lo[0] / kB; bx <= (hi[0] - 1) / kB; ++bx) {
          const Box3 b{bx, by, bz};
          Box3 c0, c1, i0, i1;
          for (int a = 0; a < 3; ++a) {
            c0[a] = b[a] * kB;
            c1[a] = std::min(c0[a] + kB, nodes_[a]);
            i0[a] = std::max(lo[a], c0[a]);
            i1[a] = std::min(hi[a], c1[a]);
          }
          f(c0, c1, i0, i1, static_cast<uint64_t>((bz * cubes_[1] + by) * cubes_[0] + bx));
        }
  }
  Box3 nodes_, cubes_{};
};

// A band's hand-over in two unlinked scratch files beside the output, whether or not it fits the
// budget (`fits`: BandHandover::fits_budget).
class ScratchHandover : public BandHandover {
 public:
  ScratchHandover(const std::string& dir, const Box3& nodes, bool fits = false)
      : BandHandover(nodes), blocks_(nodes), values_(dir), children_(dir), fits_(fits) {}
  bool fits_budget() const override { return fits_; }
  // Whether the file system gives both files their whole size now (ScratchFile::reserve).
  bool reserve() const noexcept {
    return values_.reserve(blocks_.slots() * sizeof(float)) && children_.reserve(blocks_.slots() * sizeof(Record));
  }
  void write_box(const Box3& lo, const Box3& hi, const float* v, const Record* r, int64_t row, int64_t plane) override {
    blocks_.write(values_, 0, lo, hi, v, row, plane);
    blocks_.write(children_, 0, lo, hi, r, row, plane);
  }
  void read_values(const Box3& lo, const Box3& hi, float* out, int64_t row, int64_t plane) const override {
    blocks_.read(values_, 0, lo, hi, out, row, plane);
  }
  void read_children(const Box3& lo, const Box3& hi, Record* out, int64_t row, int64_t plane) const override {
    blocks_.read(children_, 0, lo, hi, out, row, plane);
  }

 private:
  BlockedEntries blocks_;
  ScratchFile values_, children_;
  bool fits_;
};

// A band's hand-over to the next in one named file beside the output, which every rank of a
// distributed convert writes its tiles' parts into and reads the whole of for the next band.
class SharedHandover : public BandHandover {
 public:
  SharedHandover(const std::string& path, SharedFile::Mode mode, const Box3& nodes)
      : BandHandover(nodes), blocks_(nodes), file_(path, mode), records_at_(blocks_.slots() * sizeof(float)) {}
  void write_box(const Box3& lo, const Box3& hi, const float* v, const Record* r, int64_t row, int64_t plane) override {
    blocks_.write(file_, 0, lo, hi, v, row, plane);
    blocks_.write(file_, records_at_, lo, hi, r, row, plane);
  }
  void read_values(const Box3& lo, const Box3& hi, float* out, int64_t row, int64_t plane) const override {
    blocks_.read(file_, 0, lo, hi, out, row, plane);
  }
  void read_children(const Box3& lo, const Box3& hi, Record* out, int64_t row, int64_t plane) const override {
    blocks_.read(file_, records_at_, lo, hi, out, row, plane);
  }

 private:
  BlockedEntries blocks_;
  SharedFile file_;
  uint64_t records_at_;
};

}  // namespace isotope
