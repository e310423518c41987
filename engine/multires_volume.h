#pragma once
// A volume prepared for adaptive extraction: embedded in a (2^k+1)^3 lattice and annotated with
// one saturated record per refinement vertex (design.md, "Per-vertex record").
#include <array>
#include <cstdint>
#include <vector>

#include "engine/brick_layout.h"
#include "engine/lattice.h"
#include "engine/volume.h"

namespace isotope {

// What every visit of the traversal reads: saturated range and errors of v's diamond.
struct DiamondBounds {
  float lo = 0, hi = 0;      // value range of every node below v
  float error_bound = 0;     // guaranteed L-infinity bound (infinite where the diamond leaves the data box)
  float error_surplus = 0;   // the paper's saturated surplus eta_bar
};

// What only a tetrahedron that the error would let stop reads. Intervals are half-open
// [lo, hi), empty when lo >= hi.
struct DiamondTopology {
  float exact_lo = 1, exact_hi = 0;  // hull X_bar of isovalues where the exact rule fires
  float paper_lo = 1, paper_hi = 0;  // hull I_bar of the paper's critical intervals
  float weight = 0;                  // saturated simplification weight (max of |X|)
};

struct PreprocessStats {
  int64_t critical_paper[3] = {0, 0, 0};  // per diamond type (cube, octahedron, diamond): paper's flag at f(v)
  int64_t critical_exact[3] = {0, 0, 0};  // exact rule fires for some isovalue
  double seconds = 0;
};

class MultiresVolume {
 public:
  // Embeds and preprocesses (in parallel). Throws std::invalid_argument for dims < 2 or
  // non-finite values.
  static MultiresVolume build(const Volume& volume);

  const Lattice& lattice() const { return lattice_; }
  const std::array<int64_t, 3>& data_dims() const { return data_dims_; }
  const std::array<double, 3>& spacing() const { return spacing_; }
  const std::array<double, 3>& origin() const { return origin_; }
  const PreprocessStats& stats() const { return stats_; }

  int64_t slot(const Coord& c) const { return layout_.slot(c[0], c[1], c[2]); }
  // Value at any lattice node (replicated from the nearest data node outside the data box).
  float value(int64_t slot) const { return values_[static_cast<size_t>(slot)]; }
  float value(const Coord& c) const { return value(slot(c)); }
  const DiamondBounds& bounds(int64_t slot) const { return bounds_[static_cast<size_t>(slot)]; }
  const DiamondTopology& topology(int64_t slot) const { return topology_[static_cast<size_t>(slot)]; }

 private:
  friend class RecordBuilder;
  Lattice lattice_;
  BrickLayout layout_;
  std::array<int64_t, 3> data_dims_{};
  std::array<double, 3> spacing_{1, 1, 1};
  std::array<double, 3> origin_{0, 0, 0};
  std::vector<float> values_;
  std::vector<DiamondBounds> bounds_;
  std::vector<DiamondTopology> topology_;
  PreprocessStats stats_;
};

}  // namespace isotope
