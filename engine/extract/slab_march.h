#pragma once
// Marching tetrahedra over z-slabs of cells on all threads, joined into the mesh of one walk over
// the slabs in order: what the full-resolution baseline (extract_full_resolution) and the
// finest-level extraction (extract_finest) share.
#include <algorithm>
#include <array>
#include <cstdint>
#include <functional>

#include "engine/mesh/marching_tetrahedra.h"
#include "isotope/distribution.h"
#include "isotope/mesh.h"

namespace isotope {

struct SlabPlan {
  int64_t cell_layers = 0;  // cells along z
  int64_t slab_layers = 1;  // cell layers per slab: slab s covers [s * slab_layers, ...)
  int64_t side = 2;         // the MeshBuilder's grid side (fixes the edge keys)
  // Nodes along x and y of the cells marched (at most side each; 0: side): what bounds the mesh.
  std::array<int64_t, 2> layer_nodes{0, 0};
  float iso = 0;
  std::array<double, 3> origin{0, 0, 0}, spacing{1, 1, 1};
};

// Feeds the cells of layers [z_begin, z_end) to the builder. Must touch no vertex off those
// layers' nodes; may be called concurrently for different slabs.
using MarchSlab = std::function<void(int64_t z_begin, int64_t z_end, MeshBuilder& builder)>;

// Runs march on every slab, in parallel, and joins the meshes in slab order: vertices are numbered
// in order of first appearance in one walk over the slabs in order, so the mesh is the same bit for
// bit whatever the number of threads. A slab is joined as soon as the slabs before it are, into a
// mesh reserved as address space, so only the slabs in flight are held beside it; where the
// reservation is refused, all are marched first and then joined (docs/METHOD.md, "eps = 0 by
// blocks"). A slab that throws (its march, its builder) stops the others from starting;
// on_failure, if given, is called inside the handler first (it may use std::current_exception), for
// march functions that wait on one another.
Mesh march_in_slabs(const SlabPlan& plan, const MarchSlab& march, const std::function<void()>& on_failure = {});

// An extraction leaves its slabs' builders and arrays, up to 64 MB, and its threads' edge memos
// (march_block) to the next one in the process; this lets them go (a server gone idle).
void give_back_slab_memory();

inline int64_t slab_count(const SlabPlan& plan) {
  return std::max<int64_t>(0, (plan.cell_layers + plan.slab_layers - 1) / plan.slab_layers);
}

// Spread over processes (isotope::Distribution): this one marches slabs [first, last),
// and rank 0 joins every process's slabs in slab order (each process's share is a contiguous run
// of them), so that its mesh is the one march_in_slabs makes, bit for bit. Other ranks get an
// empty mesh. Collective; a failure anywhere throws DistributedError everywhere.
// `seconds`: set to the time this process took for its own slabs. `keep_share`: every rank joins
// only its own slabs and keeps that mesh (RunContext::keep_shares). `on_failure`: as above.
Mesh march_in_slabs(const SlabPlan& plan, const MarchSlab& march, const Distribution& group, int64_t first,
                    int64_t last, double* seconds, bool keep_share, const std::function<void()>& on_failure = {});

}  // namespace isotope
