#pragma once
// Joining the meshes of the traversal's pieces (extract_adaptive) into one.
#include <cstdint>
#include <vector>

#include "engine/hierarchy/kuhn.h"
#include "isotope/mesh.h"

namespace isotope {

// What one piece produced: its own welded mesh, the edge key of each of its vertices, counts, and
// the tetrahedron the piece covers (lattice coordinates).
struct PartMesh {
  Mesh mesh;
  std::vector<uint64_t> keys;
  int64_t tets_visited = 0, tets_emitted = 0, tets_simplified = 0;
  Tet region{};
};

// Welds the pieces' meshes in piece order, freeing each as it goes. A vertex takes the next index
// the first time its edge appears, exactly as in one pass over the pieces in order, so the result is the same,
// bit for bit, whatever the number of threads that built the pieces. Only vertices on a face of
// their piece's tetrahedron can appear in another piece, so only those go through a welding
// table. `side`: nodes per lattice axis. `room_to_clip`: the mesh will be clipped to the data box
// (clip_to_box), so its arrays are reserved with room for what that adds, a few
// triangles and vertices along the far faces, instead of growing by a copy of the whole mesh.
Mesh weld(std::vector<PartMesh>& parts, int64_t side, bool room_to_clip = false);

}  // namespace isotope
