#include "engine/hierarchy/multires_volume.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "engine/core/parallel.h"
#include "engine/core/volume_check.h"
#include "engine/hierarchy/record_builder.h"

namespace isotope {
namespace {}  // namespace

// The in-memory arrays as RecordBuilder's grid.
namespace {

class VolumeGrid {
 public:
  explicit VolumeGrid(MultiresVolume& mv) : mv_(mv) {}
  const Lattice& lattice() const { return mv_.lattice(); }
  const std::array<int64_t, 3>& data_dims() const { return mv_.data_dims(); }
  float value(const Coord& c) const { return mv_.value(c); }
  bool child(const Coord& u, Record& r) const {
    if (!mv_.has_record(u)) return false;
    const int64_t s = mv_.record_slot(u);
    r.bounds = mv_.bounds(s);
    r.topology = mv_.topology(s);
    return true;
  }
  void store(const Coord& v, const Record& r) { mv_.set_record(v, r); }

  void copy_values(const Volume& volume) const {
    parallel_for(int64_t{0}, volume.dims[2], [&](int64_t z) {
      for (int64_t y = 0; y < volume.dims[1]; ++y)
        for (int64_t x = 0; x < volume.dims[0]; ++x) mv_.set_value(x, y, z, volume.at(x, y, z));
    });
  }

 private:
  MultiresVolume& mv_;
};

}  // namespace

MultiresVolume MultiresVolume::allocate(const std::array<int64_t, 3>& dims, const std::array<double, 3>& spacing,
                                        const std::array<double, 3>& origin) {
  validate_dims(dims);
  MultiresVolume mv;
  mv.lattice_ = Lattice::enclosing(dims);
  mv.data_dims_ = dims;
  mv.spacing_ = spacing;
  mv.origin_ = origin;
  // Lattice nodes beyond the data box are never stored: value() answers with the nearest data
  // node, which keeps ranges tight; what a tetrahedron reaching past the box makes of them is
  // clipped to the box (docs/METHOD.md, "Volumes that are not (2^k+1)^3").
  mv.layout_ = BrickLayout(dims);
  mv.values_.resize(static_cast<size_t>(mv.layout_.size));
  int64_t records = 0;
  for (int j = 0; j <= mv.lattice_.k; ++j) {
    mv.scale_layout_.emplace_back(std::array<int64_t, 3>{
        (mv.record_extent(0, j) >> j) + 1, (mv.record_extent(1, j) >> j) + 1, (mv.record_extent(2, j) >> j) + 1});
    mv.scale_offset_.push_back(records);
    records += mv.scale_layout_.back().size;
  }
  mv.bounds_.resize(static_cast<size_t>(records));
  mv.topology_.resize(static_cast<size_t>(records));
  return mv;
}

MultiresVolume MultiresVolume::build(const Volume& volume, const ProgressCallback& progress) {
  const auto start = std::chrono::steady_clock::now();
  validate_volume(volume);
  MultiresVolume mv = allocate(volume.dims, volume.spacing, volume.origin);
  std::vector<std::array<int64_t, 3>> scale_nodes;
  for (int j = 0; j <= mv.lattice_.k; ++j)
    scale_nodes.push_back(
        {(mv.record_extent(0, j) >> j) + 1, (mv.record_extent(1, j) >> j) + 1, (mv.record_extent(2, j) >> j) + 1});
  VolumeGrid grid(mv);
  const RecordBuilder<VolumeGrid> builder(grid);
  grid.copy_values(volume);
  int64_t work = 0;  // nodes of each scale that are not all-even there, i.e. not coarser
  for (int j = 0; j < mv.lattice_.k; ++j) {
    const auto& n = scale_nodes[static_cast<size_t>(j)];
    work += n[0] * n[1] * n[2] - (n[0] + 1) / 2 * ((n[1] + 1) / 2) * ((n[2] + 1) / 2);
  }
  ProgressReporter reporter(progress, work);
  std::atomic<int64_t> paper[3] = {0, 0, 0}, exact[3] = {0, 0, 0};
  // Bottom-up, level by level (paper Sec. 3.2): scale j = 0 is the finest, and within a scale
  // edge midpoints (m = 1) are finer than face centres (m = 2), which are finer than cube centres.
  // In units of 2^j, a node of scale j has m odd coordinates. Nodes are visited brick by brick
  // of their scale's layout, so the children's records a node reads are close by.
  constexpr int64_t kWidth = int64_t{1} << BrickLayout::kBits;
  for (int j = 0; j < mv.lattice_.k; ++j) {
    const std::array<int64_t, 3> nodes = scale_nodes[static_cast<size_t>(j)];
    const int64_t bx = (nodes[0] + kWidth - 1) / kWidth, by = (nodes[1] + kWidth - 1) / kWidth,
                  bz = (nodes[2] + kWidth - 1) / kWidth;
    for (int m = 1; m <= 3; ++m) {
      parallel_for(int64_t{0}, bz * by, [&](int64_t bzy) {
        CriticalCounts counts = {{0, 0, 0}, {0, 0, 0}};
        int64_t built = 0;
        const int64_t z0 = bzy / by * kWidth, y0 = bzy % by * kWidth;
        for (int64_t x0 = 0; x0 < bx * kWidth; x0 += kWidth)
          for (int odd = 0; odd < 8; ++odd) {  // which of x, y, z are odd (in units of 2^j)
            const int ox = odd & 1, oy = (odd >> 1) & 1, oz = odd >> 2;
            if (ox + oy + oz != m) continue;
            for (int64_t z = z0 + oz; z < std::min(z0 + kWidth, nodes[2]); z += 2)
              for (int64_t y = y0 + oy; y < std::min(y0 + kWidth, nodes[1]); y += 2)
                for (int64_t x = x0 + ox; x < std::min(x0 + kWidth, nodes[0]); x += 2, ++built)
                  builder.build({x << j, y << j, z << j}, counts);
          }
        for (int t = 0; t < 3; ++t) {
          paper[t] += counts[0][t];
          exact[t] += counts[1][t];
        }
        reporter.advance(built);
      });
    }
  }
  for (int t = 0; t < 3; ++t) {
    mv.stats_.critical_paper[t] = paper[t];
    mv.stats_.critical_exact[t] = exact[t];
  }
  mv.stats_.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return mv;
}

}  // namespace isotope
