#pragma once
// A volume prepared for adaptive extraction: embedded in a (2^k+1)^3 lattice and annotated with
// one saturated record per refinement vertex (docs/METHOD.md, "Per-vertex records").
#include <algorithm>
#include <array>
#include <bit>
#include <cstdint>
#include <vector>

#include "engine/core/huge_blocks.h"
#include "engine/core/progress_reporter.h"
#include "engine/hierarchy/brick_layout.h"
#include "engine/hierarchy/lattice.h"
#include "engine/hierarchy/record.h"
#include "isotope/volume.h"

namespace isotope {

struct PreprocessStats {
  int64_t critical_paper[3] = {0, 0, 0};  // per diamond type (cube, octahedron, diamond): paper's flag at f(v)
  int64_t critical_exact[3] = {0, 0, 0};  // exact rule fires for some isovalue
  double seconds = 0;
};

class MultiresVolume {
 public:
  // Embeds and preprocesses (in parallel). Throws InvalidInput for dims < 2 or
  // non-finite values. `progress`, if given, hears the fraction done (see ProgressReporter).
  static MultiresVolume build(const Volume& volume, const ProgressCallback& progress = {});
  // An empty volume of these dimensions, to be filled with set_value and set_record (a store
  // being loaded). Throws InvalidInput as build does.
  static MultiresVolume allocate(const std::array<int64_t, 3>& dims, const std::array<double, 3>& spacing,
                                 const std::array<double, 3>& origin);
  void set_value(int64_t x, int64_t y, int64_t z, float f) { values_[static_cast<size_t>(layout_.slot(x, y, z))] = f; }
  void set_record(const Coord& v, const Record& r) {
    const auto s = static_cast<size_t>(record_slot(v));
    bounds_[s] = r.bounds;
    topology_[s] = r.topology;
  }
  void set_stats(const PreprocessStats& stats) { stats_ = stats; }

  // Values and records may be held as integer codes of a quantized store: a data value is then
  // value_offset + value_scale * code, and extract() maps isovalue and thresholds onto codes.
  double value_offset() const { return value_offset_; }
  double value_scale() const { return value_scale_; }
  void set_value_map(double offset, double scale) { value_offset_ = offset, value_scale_ = scale; }

  const Lattice& lattice() const { return lattice_; }
  const std::array<int64_t, 3>& data_dims() const { return data_dims_; }
  const std::array<double, 3>& spacing() const { return spacing_; }
  const std::array<double, 3>& origin() const { return origin_; }
  const PreprocessStats& stats() const { return stats_; }

  // Value at any lattice node: outside the data box, that of the nearest data node.
  float value(const Coord& c) const {
    const int64_t x = std::min(c[0], data_dims_[0] - 1), y = std::min(c[1], data_dims_[1] - 1),
                  z = std::min(c[2], data_dims_[2] - 1);
    return values_[static_cast<size_t>(layout_.slot(x, y, z))];
  }

  // Values of nodes (x, y, z) .. (x + count - 1, y, z), all in the data box, into out: a brick's
  // row at a time.
  void value_row(int64_t x, int64_t y, int64_t z, int64_t count, float* out) const {
    while (count > 0) {
      const int64_t run = std::min(count, BrickLayout::kMask + 1 - (x & BrickLayout::kMask));
      const float* row = values_.data() + layout_.slot(x, y, z);
      std::copy(row, row + run, out);
      x += run, out += run, count -= run;
    }
  }

  // Records of scale j (Record) have their own bricked array over the multiples of 2^j:
  // the coarse levels take little memory and stay in cache, and the records of one subtree lie
  // together. Each array stops at record_extent.
  bool has_record(const Coord& v) const {
    const int j = scale_of(v);
    for (int a = 0; a < 3; ++a)
      if (v[a] > record_extent(a, j)) return false;
    return true;
  }
  int64_t record_slot(const Coord& v) const {
    const int j = scale_of(v);
    return scale_offset_[static_cast<size_t>(j)] +
           scale_layout_[static_cast<size_t>(j)].slot(v[0] >> j, v[1] >> j, v[2] >> j);
  }
  // Largest coordinate along axis a with a record at scale j.
  int64_t record_extent(int a, int j) const { return isotope::record_extent(lattice_, data_dims_, a, j); }
  int64_t memory_bytes() const {
    return static_cast<int64_t>(values_.size() * sizeof(float) + bounds_.size() * sizeof(DiamondBounds) +
                                topology_.size() * sizeof(DiamondTopology));
  }
  const DiamondBounds& bounds(int64_t record) const { return bounds_[static_cast<size_t>(record)]; }
  const DiamondTopology& topology(int64_t record) const { return topology_[static_cast<size_t>(record)]; }

 private:
  Lattice lattice_;
  int scale_of(const Coord& v) const { return isotope::scale_of(v, lattice_); }

  BrickLayout layout_;                     // values: the data box
  std::vector<BrickLayout> scale_layout_;  // records: one layout per scale 0..k
  std::vector<int64_t> scale_offset_;
  std::array<int64_t, 3> data_dims_{};
  std::array<double, 3> spacing_{1, 1, 1};
  std::array<double, 3> origin_{0, 0, 0};
  std::vector<float, detail::HugePageAllocator<float>> values_;
  std::vector<DiamondBounds, detail::HugePageAllocator<DiamondBounds>> bounds_;
  std::vector<DiamondTopology, detail::HugePageAllocator<DiamondTopology>> topology_;
  PreprocessStats stats_;
  double value_offset_ = 0, value_scale_ = 1;
};

}  // namespace isotope
