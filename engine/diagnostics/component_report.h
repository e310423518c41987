#pragma once
// Per-component measures of a triangle mesh, and a comparison of two meshes of one isosurface
// (full resolution against adaptive) that names what the coarse mesh did to each component:
// lost, appeared, merged, split, handles closed or opened.
//
// Orientation: triangles are counter-clockwise seen from the outside (value <= iso), so normals
// point from the inside (value > iso) to the outside. The divergence theorem then gives a
// positive signed volume for a closed component that bounds a region of value > iso from
// outside (a ball, the outer wall of a shell: generate_nested_spheres) and a negative one for a component
// that bounds such a region from within (the inner wall of a hollow shell, whose normals point
// into the cavity).
//
// Matching rule of compare_components, with the reason for each step:
//  1. Each mesh is reduced to surface samples: its vertices plus, on triangles with an edge
//     longer than tolerance, points of a barycentric lattice of spacing tolerance / 2; then one
//     sample per (cell of size tolerance / 3, component), the first in that order. Vertices
//     alone would undersample a coarse mesh, whose large flat triangles hold few vertices, and
//     counting vertices would weigh a component by its triangle density; thinned samples weigh
//     every component by its area on both sides, so the shares of step 3 mean the same thing
//     for both meshes.
//  2. Every sample of one mesh (at most ~200k: beyond that a hashed subset that keeps at least
//     64 of each component) looks up the nearest sample of the other within `tolerance` (a
//     uniform hash grid of cell size tolerance, 27 cells; ties to the lowest index) and counts
//     one hit for the pair (its component, the other's). A sample with nothing within
//     tolerance counts for nothing: it is surface the other mesh does not have there.
//     Nearest rather than every neighbour, so that a component merely passing close to another
//     does not relate to it.
//  3. A full and an adaptive component are related when at least 10% of the samples of either
//     one hit the other (at least one hit for a component with fewer than 10 samples). Either
//     side, because a small component merged into a large one is a small share of the large one
//     but all of itself; a share rather than any hit, because a component that touches another
//     within tolerance along a seam is not that component.
//  4. The connected groups of this bipartite relation are classified by their sizes (one full
//     to none: lost; none to one: appeared; many to one: merged; one to many: split; many to
//     many: rearranged) and one-to-one pairs by their topology (see ChangeKind). A many-to-many
//     group with as many components on each side is first tried as one-to-one pairs: when every
//     component has a clear favourite (the largest share of its samples, at least twice the
//     next) that picks it back, each pair is classified alone. Noise specks a voxel or two apart otherwise relate to
//     each other's counterparts and read as "rearranged" where nothing changed (hydrogen at iso 0.001, preserve); a
//     join moved from A-B to B-C still reads as rearranged.
// Limits: components within `tolerance` of each other over a large share of their area (e.g. two
// walls of a shell thinner than the tolerance) cannot be told apart. If the lattice points would
// outnumber the triangles of both meshes (and 4 M), their spacing is doubled until they do not,
// which only happens for a tolerance below the full-resolution triangles' size; thinning cells
// are at least 2^-20 of the meshes' extent.
#include <array>
#include <cstdint>
#include <optional>
#include <string_view>
#include <utility>
#include <vector>

#include "isotope/mesh.h"

namespace isotope {

// Measures of one connected component (triangles connected through shared vertices, as in
// measure_topology).
struct ComponentStats {
  int64_t triangles = 0;
  int64_t vertices = 0;
  int64_t edges = 0;                 // distinct undirected edges
  int64_t boundary_edges = 0;        // with one incident triangle
  int64_t nonmanifold_edges = 0;     // with three or more
  int64_t euler_characteristic = 0;  // V - E + F of the component
  bool closed = false;               // no boundary and no non-manifold edges
  // Closed only, and only when 2 - chi is even and >= 0 (otherwise a pinched vertex makes the
  // formula meaningless): (2 - chi) / 2.
  std::optional<int64_t> genus;
  std::array<double, 3> bbox_min{0, 0, 0}, bbox_max{0, 0, 0};
  double area = 0;
  std::optional<double> volume;  // closed only: |signed volume| by the divergence theorem
  // Closed only: signed volume > 0, i.e. the component bounds a region of value > iso from
  // outside (see the orientation note above); false for the inner wall of a hollow shell.
  bool encloses_inside = false;

  bool operator==(const ComponentStats&) const = default;
};

// The components of a mesh and which component each vertex belongs to.
struct MeshComponents {
  // By triangles descending, then bbox_min lexicographic, then lowest vertex index.
  std::vector<ComponentStats> components;
  std::vector<int32_t> vertex_component;  // per position: index into components, -1 if unreferenced

  bool operator==(const MeshComponents&) const = default;
};

// Throws InvalidInput when a triangle refers to a missing vertex or the mesh has 2^31
// or more vertices. The edges are found on all threads, as measure_topology finds them.
MeshComponents label_components(const Mesh& mesh);
// What measure_topology gives, from the mesh's components: their sums, with no second pass over
// the mesh.
MeshTopology total_topology(const std::vector<ComponentStats>& components);
// label_components(mesh).components.
std::vector<ComponentStats> measure_components(const Mesh& mesh);

enum class ChangeKind {
  lost,            // a full component with no adaptive counterpart
  appeared,        // an adaptive component with no full counterpart
  merged,          // several full components -> one adaptive
  split,           // one full component -> several adaptive
  rearranged,      // several -> several
  handles_closed,  // one-to-one, both closed, adaptive genus < full genus
  handles_opened,  // one-to-one, both closed, adaptive genus > full genus
  // One-to-one, not both closed with a genus: the Euler characteristic or closedness differs.
  euler_changed,
};
std::string_view to_string(ChangeKind kind);

// One group of related components whose topology differs between the meshes.
struct ComponentChange {
  ChangeKind kind = ChangeKind::lost;
  std::vector<int> full;      // indices into ComponentComparison::full_components, ascending
  std::vector<int> adaptive;  // indices into ComponentComparison::adaptive_components, ascending
  // Total genus of the adaptive side minus that of the full side; 0 when a component of the
  // group has no genus (open), in which case euler_change tells the difference.
  int64_t genus_change = 0;
  int64_t euler_change = 0;  // total Euler characteristic, adaptive minus full

  bool operator==(const ComponentChange&) const = default;
};

struct ComponentComparison {
  std::vector<ComponentStats> full_components, adaptive_components;
  // Ordered by lowest full index; groups with no full component (appeared) last, by adaptive index.
  std::vector<ComponentChange> changes;
  // One-to-one pairs (full, adaptive) of the same genus (closed) or the same Euler
  // characteristic and closedness (open), ascending.
  std::vector<std::pair<int, int>> matched_unchanged;
  // Surface samples (matching rule, step 1) that looked for a neighbour, per side, and those that
  // found one within tolerance: a low share means the tolerance is too small for how far the
  // adaptive surface moved.
  int64_t full_samples = 0, adaptive_samples = 0;
  int64_t full_samples_matched = 0, adaptive_samples_matched = 0;

  bool operator==(const ComponentComparison&) const = default;
};

// Relates the components of two meshes of one isosurface by the matching rule above and reports
// every group whose topology differs. `tolerance`: how far the adaptive surface may lie from the
// full one (physical units; a few voxel spacings for coarse meshes). A component that moved
// farther than that shows as lost plus appeared: the *_samples_matched counts tell. Deterministic,
// serial. Throws InvalidInput for a tolerance that is not finite and > 0 or is below
// 2^-30 of the meshes' extent (grid cells are 32-bit), and as label_components.
ComponentComparison compare_components(const Mesh& full, const Mesh& adaptive, double tolerance);
// The same with the components already labelled (label_components of each mesh; throws
// InvalidInput when the labels do not have one entry per position).
ComponentComparison compare_components(const Mesh& full, const MeshComponents& full_components, const Mesh& adaptive,
                                       const MeshComponents& adaptive_components, double tolerance);

}  // namespace isotope
