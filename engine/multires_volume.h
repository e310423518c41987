#pragma once
// A volume prepared for adaptive extraction: embedded in a (2^k+1)^3 grid and annotated with
// one saturated record per refinement vertex (design.md, "Per-vertex record").
#include <array>
#include <cstdint>
#include <vector>

#include "engine/lattice.h"
#include "engine/volume.h"

namespace isotope {

// Saturated per-vertex record: everything the stopping rule of one diamond reads.
struct DiamondRecord {
  float error_bound = 0;    // guaranteed L-infinity bound below v (infinite where v's diamond leaves the data box)
  float error_surplus = 0;  // the paper's saturated surplus eta_bar
  float lo = 0, hi = 0;     // value range of every node below v
  float exact_lo = 1, exact_hi = 0;  // hull X_bar of isovalues where the exact rule fires (empty: lo > hi)
  float paper_lo = 1, paper_hi = 0;  // hull I_bar of the paper's critical intervals
  float weight = 0;         // saturated simplification weight (max)
};

struct PreprocessStats {
  int64_t critical_paper[3] = {0, 0, 0};  // per diamond type (cube, octahedron, diamond): paper's flag at f(v)
  int64_t critical_exact[3] = {0, 0, 0};  // exact rule fires for some isovalue
  double seconds = 0;
};

class MultiresVolume {
 public:
  // Embeds and preprocesses. Throws std::invalid_argument for dims < 2 or non-finite values.
  static MultiresVolume build(const Volume& volume);

  const Lattice& lattice() const { return lattice_; }
  const std::array<int64_t, 3>& data_dims() const { return data_dims_; }
  const std::array<double, 3>& spacing() const { return spacing_; }
  const std::array<double, 3>& origin() const { return origin_; }
  const PreprocessStats& stats() const { return stats_; }

  // Value at any lattice node (mirrored outside the data box).
  float value(int64_t node) const { return values_[static_cast<size_t>(node)]; }
  const DiamondRecord& record(int64_t node) const { return records_[static_cast<size_t>(node)]; }

 private:
  Lattice lattice_;
  std::array<int64_t, 3> data_dims_{};
  std::array<double, 3> spacing_{1, 1, 1};
  std::array<double, 3> origin_{0, 0, 0};
  std::vector<float> values_;
  std::vector<DiamondRecord> records_;
  PreprocessStats stats_;
};

}  // namespace isotope
