#pragma once
// The processes one extraction is spread over, as its drivers see them (isotope::Distribution):
// alone, a step just runs and a count is this process's; spread, each step that
// may fail settles together, so that a rank whose read fails stops every rank instead of leaving
// them waiting at the next gather, and a count is summed over the ranks. A driver calls the same
// steps either way.
#include <cstdint>
#include <functional>
#include <utility>
#include <vector>

#include "engine/extract/distributed_parts.h"
#include "engine/extract/slab_march.h"
#include "isotope/distribution.h"

namespace isotope {

class ProcessGroup {
 public:
  explicit ProcessGroup(const Distribution* distribution) : distribution_(distribution) {}

  template <class Work>
  void step(const Work& work) const {
    settle_together(distribution_, work);
  }
  int64_t sum(int64_t mine) const { return distribution_ ? sum_over_ranks(*distribution_, mine) : mine; }
  // Spread over ranks: a memo of earlier choices must then be ignored, so that every rank searches
  // alike.
  bool spread() const { return distribution_ != nullptr; }

  // This process's share of N items, [first, last): all of them alone; spread, a contiguous share
  // of about the same cost on each rank, the costs of all of them (every rank computing a part
  // with cost_of(first, last, out)) kept in `costs`.
  struct Share {
    size_t first = 0, last = 0;
    std::vector<double> costs;  // spread only
  };
  Share share_of(size_t n, const std::function<void(size_t first, size_t last, double* out)>& cost_of) const {
    if (!distribution_) return {0, n, {}};
    return share_of(share_costs(*distribution_, n, cost_of));
  }
  // The same where every rank knows every item's cost alike (COSTS): no rank asks the others.
  Share share_of(std::vector<double> costs) const {
    if (!distribution_) return {0, costs.size(), {}};
    Share share;
    const std::vector<size_t> bounds = share_by_cost(costs, distribution_->ranks());
    share.first = bounds[static_cast<size_t>(distribution_->rank())];
    share.last = bounds[static_cast<size_t>(distribution_->rank()) + 1];
    share.costs = std::move(costs);
    return share;
  }
  // Every rank's load, in rank order, on every rank; none alone.
  std::vector<RankLoad> loads(const RankLoad& mine) const {
    return distribution_ ? gather_loads(*distribution_, mine) : std::vector<RankLoad>{};
  }
  // The parts the process that makes the mesh welds: its own alone, or each rank its own when it
  // keeps its share; otherwise every rank's, in rank order, on rank 0, and nothing elsewhere.
  std::vector<PartMesh> to_welder(std::vector<PartMesh> mine, bool keep_shares) const {
    if (distribution_ && !keep_shares) return gather_parts(*distribution_, std::move(mine));
    return mine;  // moved, not copied (a conditional expression would copy it)
  }
  // This process's SHARE of `plan`'s slabs marched: alone, every slab (march_in_slabs); spread,
  // its share, joined on rank 0 (or kept, with keep_shares), `seconds` its own time.
  Mesh march_slabs(const SlabPlan& plan, const MarchSlab& march, const Share& share, double* seconds, bool keep_shares,
                   const std::function<void()>& on_failure = {}) const {
    if (!distribution_) return march_in_slabs(plan, march, on_failure);
    return march_in_slabs(plan, march, *distribution_, static_cast<int64_t>(share.first),
                          static_cast<int64_t>(share.last), seconds, keep_shares, on_failure);
  }
  // Whether this process makes a mesh: alone, keeping its share, or rank 0.
  bool makes_mesh(bool keep_shares) const { return !distribution_ || keep_shares || distribution_->rank() == 0; }

 private:
  const Distribution* distribution_;
};

}  // namespace isotope
