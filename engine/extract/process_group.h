#pragma once
// The processes one extraction is spread over, as its drivers see them (isotope::Distribution):
// alone, a step just runs and a count is this process's; spread, each step that
// may fail settles together, so that a rank whose read fails stops every rank instead of leaving
// them waiting at the next gather, and a count is summed over the ranks. A driver calls the same
// steps either way.
#include <cstdint>

#include "engine/extract/distributed_parts.h"
#include "isotope/distribution.h"

namespace isotope {

class ProcessGroup {
 public:
  explicit ProcessGroup(const Distribution* distribution) : distribution_(distribution) {}

  template <class Work>
  void step(const Work& work) const {
    if (distribution_)
      settle_together(*distribution_, work);
    else
      work();
  }
  int64_t sum(int64_t mine) const { return distribution_ ? sum_over_ranks(*distribution_, mine) : mine; }
  // Spread over ranks: a memo of earlier choices must then be ignored, so that every rank searches
  // alike.
  bool spread() const { return distribution_ != nullptr; }

 private:
  const Distribution* distribution_;
};

}  // namespace isotope
