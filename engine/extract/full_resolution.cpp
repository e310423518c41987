#include "engine/extract/full_resolution.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "engine/extract/slab_march.h"
#include "engine/extract/traversal.h"
#include "engine/hierarchy/kuhn.h"
#include "engine/mesh/marching_tetrahedra.h"

namespace isotope {
namespace {

// Cells per slab: enough work to pay for a task, a welding table and a merge step, few enough
// that a 257^3 volume gives dozens of slabs to balance over the threads, and a 65^3 one a single
// slab (nothing to merge).
constexpr int64_t kSlabCells = int64_t{1} << 18;

// Marching tetrahedra over the cells of layers [z_begin, z_end), in the serial walk's order.
void march_layers(const Volume& volume, float iso, int64_t z_begin, int64_t z_end, MeshBuilder& builder) {
  const auto& d = volume.dims;
  const float* values = volume.data();  // once, not per value (Volume::at chooses where they are)
  const auto at = [&](int64_t x, int64_t y, int64_t z) { return values[volume.index(x, y, z)]; };
  for (int64_t z = z_begin; z < z_end; ++z)
    for (int64_t y = 0; y + 1 < d[1]; ++y)
      for (int64_t x = 0; x + 1 < d[0]; ++x) {
        int above = 0;
        for (int c = 0; c < 8; ++c) above += at(x + (c & 1), y + ((c >> 1) & 1), z + (c >> 2)) > iso;
        if (above == 0 || above == 8) continue;
        for (const Tet& t : cell_tetrahedra({x, y, z}))
          builder.add_tet(t,
                          {at(t[0][0], t[0][1], t[0][2]), at(t[1][0], t[1][1], t[1][2]), at(t[2][0], t[2][1], t[2][2]),
                           at(t[3][0], t[3][1], t[3][2])},
                          traversal::orientation(t) > 0);
      }
}

}  // namespace

int64_t full_resolution_slab_layers(const std::array<int64_t, 3>& dims) {
  const int64_t layer_cells = std::max<int64_t>((dims[0] - 1) * (dims[1] - 1), 1);
  return std::max<int64_t>((kSlabCells + layer_cells - 1) / layer_cells, 1);
}

Mesh extract_full_resolution(const Volume& volume, float iso) {
  if (!std::isfinite(iso)) throw std::invalid_argument("the isovalue must be a finite number");
  const auto& d = volume.dims;
  SlabPlan plan;
  plan.cell_layers = std::max<int64_t>(d[2] - 1, 0);
  plan.slab_layers = full_resolution_slab_layers(d);
  // The welding keys, and so the quadrilateral splits, depend on the side: the same for all slabs.
  plan.side = std::max({d[0], d[1], d[2]});
  plan.layer_nodes = {d[0], d[1]};
  plan.iso = iso;
  plan.origin = volume.origin;
  plan.spacing = volume.spacing;
  return march_in_slabs(plan, [&](int64_t z_begin, int64_t z_end, MeshBuilder& builder) {
    march_layers(volume, iso, z_begin, z_end, builder);
  });
}

}  // namespace isotope
