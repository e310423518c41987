#pragma once
// An extraction spread over processes (isotope::Distribution): what each process's share
// of the traversal's pieces is estimated to cost, and how the pieces' meshes and each process's
// load travel to rank 0, which welds them in piece order as one process would
// (extract_adaptive).
#include <algorithm>
#include <functional>
#include <vector>

#include "engine/core/parallel.h"
#include "engine/extract/traversal.h"
#include "engine/mesh/piece_weld.h"
#include "isotope/distribution.h"
#include "isotope/extract.h"

namespace isotope {

// The levels below a piece that its cost estimate looks: deep enough to see where the surface
// and the refinement go (2^9 subtrees under a piece at most), shallow enough to read only bands
// 2 and coarser (1/64 of the data and less), so that estimating reads little of what the
// pieces themselves will read.
inline int cost_level(const Lattice& lattice, int piece_level) {
  return std::min({lattice.max_level(), piece_level + 9, std::max(piece_level, 3 * (lattice.k - 3) + 2)});
}

// Per piece of [first, last): the subtrees of cost_level() below it that the traversal reaches
// (Traversal::reach), into out[0 .. last - first). The same numbers on every process: the same
// records, read the same way.
template <TraversalSource Source>
void piece_costs(const Source& source, const traversal::SplitRule& rule, const std::vector<traversal::Piece>& pieces,
                 size_t first, size_t last, double* out) {
  parallel_for(static_cast<int64_t>(first), static_cast<int64_t>(last), [&](int64_t i) {
    const traversal::Piece& p = pieces[static_cast<size_t>(i)];
    traversal::Traversal<Source> t(source, rule);
    out[static_cast<size_t>(i) - first] = static_cast<double>(t.reach(p, cost_level(source.lattice(), p.level)));
  });
}

// Collective: the costs of items [0, n), each rank computing a contiguous 1/R of them with
// compute(first, last, out) (under settle_together) and every rank getting all of them: what the
// estimate reads is read once across the ranks, not once on each.
std::vector<double> share_costs(const Distribution& group, size_t n,
                                const std::function<void(size_t first, size_t last, double* out)>& compute);

// Collective: the sum of every process's count, on every process.
int64_t sum_over_ranks(const Distribution& group, int64_t mine);

// Collective: every process's load, on every process, in rank order.
std::vector<RankLoad> gather_loads(const Distribution& group, const RankLoad& mine);

// Collective: every process's parts, in rank order, on rank 0 (each process's parts are a
// contiguous run of the pieces, so that is piece order); nothing elsewhere. Frees `mine`.
std::vector<PartMesh> gather_parts(const Distribution& group, std::vector<PartMesh> mine);

}  // namespace isotope
