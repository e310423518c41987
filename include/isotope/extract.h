#pragma once
// What a user chooses for one extraction (what the mesh is; how the call runs is a RunContext), and
// what it reports. Every extraction checks its options with ExtractOptions::validate(); the faces
// read them from text or from their own values with the same words (docs/DESIGN.md, "Seams").
#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <isotope/distribution.h>
#include <isotope/error.h>
#include <isotope/mesh.h>
#include <isotope/run_context.h>
#include <isotope/volume.h>

namespace isotope {

// Which saturated error a tetrahedron's refinement vertex is judged by (docs/METHOD.md, "Per-vertex
// records").
enum class ErrorIndicator {
  bound,    // guaranteed L-infinity deviation of the coarse interpolant from the data (default)
  surplus,  // the paper's |f(v) - (f(a)+f(b))/2|, saturated by max
};

enum class TopologyMode {
  none,      // refine by error only (paper Sec. 3)
  paper,     // the paper's critical points and intervals (Sec. 4.2-4.4), faithfully
  preserve,  // the exact local rule (docs/METHOD.md): keeps components and Euler characteristic
  simplify,  // the exact rule, but critical points of weight < delta may go (paper Sec. 5)
};

// What makes a critical point worth keeping in `simplify` mode (paper Sec. 5.1), computed by
// convert for every vertex and saturated as a max. X is the exact rule's interval of isovalues.
enum class SimplificationWeight {
  interval,  // |X|: how far the isovalue may move while the feature exists (value units)
  gradient,  // |X| times the steepest gradient of the tetrahedra around v (value^2 per voxel)
  size,      // full-resolution tetrahedra covered by those around v that isovalues in X cut
};

// Finer near a point of interest: eps is scaled by min(1, distance / radius), so the mesh is as
// fine as the data at the point and as coarse as eps from `radius` on (distances in the
// output's coordinates, i.e. origin + spacing * index).
struct Focus {
  std::array<double, 3> point{0, 0, 0};
  double radius = 1;
};

// The largest triangle budget any face accepts.
inline constexpr int64_t kMaxTriangleBudget = int64_t{1} << 40;

// Tie classes (ExtractOptions::eps_ties): a diamond of level l falls in class l * kTieBuckets plus
// one of kTieBuckets buckets by a hash of its position, so the classes run coarse to fine and each
// level's are spread evenly over the volume. Class numbers stay below kMaxTieClasses.
inline constexpr int kTieBuckets = 16;
inline constexpr int kMaxTieClasses = 64 * kTieBuckets;

struct ExtractOptions {
  float iso = 0.0f;  // inside means value > iso
  double eps = 0.0;  // refine while the chosen error is >= eps; 0 gives full resolution
  // >= 0: of the diamonds whose key equals eps exactly, refine only those of tie class < eps_ties
  // (docs/METHOD.md, "Focus and triangle budget"): a step between eps and the next key above it,
  // which a triangle budget takes to land closer to what it was given. -1: all of them (key >= eps).
  int eps_ties = -1;
  ErrorIndicator error = ErrorIndicator::bound;
  TopologyMode topology = TopologyMode::preserve;
  SimplificationWeight weight = SimplificationWeight::interval;  // simplify mode only
  double delta = 0.0;  // simplify mode: critical points of weight < delta may be dropped
  std::optional<Focus> focus;
  // > 0: the finest eps whose mesh has at most this many triangles (eps must then be 0); on
  // volumes over 257 samples on a side, an eps whose mesh has between 90% and 100% of them, chosen from a
  // sample, when one does (ExtractStats::budget_sampled).
  int64_t max_triangles = 0;
  // With max_triangles in simplify mode: choose delta too: the smallest delta whose coarsest mesh
  // takes at most half the budget (features of smallest weight dropped first), then the finest eps
  // within the whole budget. delta must be 0.
  bool auto_delta = false;

  // Throws OptionError naming the first option out of its range: iso not finite, eps or delta
  // negative or NaN (infinity is the coarsest), eps_ties outside -1 .. kMaxTieClasses or with an
  // infinite eps (or with a budget), delta without `simplify`, a focus point not finite or a
  // radius not > 0, a budget outside [0, kMaxTriangleBudget] or with eps > 0, auto_delta without a budget in
  // simplify mode. Every extraction calls it; a face calls it to refuse before any work.
  void validate() const;
};

// The names of the values, as every face spells them ("preserve", "surplus").
std::string_view to_string(ErrorIndicator e);
std::string_view to_string(TopologyMode t);
std::string_view to_string(SimplificationWeight w);

// What one process of a distributed extraction did (isotope/distribution.h).
struct RankLoad {
  double cost = 0;          // its share of the estimated cost (the unit is the estimate's own)
  int64_t items = 0;        // pieces (or slabs at eps 0) in its share
  int64_t work = 0;         // tetrahedra it visited (at eps 0: cells it marched)
  double seconds = 0;       // running its share
  uint64_t bytes_read = 0;  // compressed bytes its store cache read, from opening the store on
};

// What an extraction measured of itself.
struct ExtractStats {
  int64_t tets_visited = 0;
  int64_t tets_emitted = 0;  // stopping tetrahedra that were handed to marching tetrahedra
  // Simplify mode: stopping tetrahedra that preserve would have refined (a critical point below
  // fires at the isovalue, but its weight is under delta). 0 means the mesh is preserve's.
  int64_t tets_simplified = 0;
  double seconds = 0;
  // With max_triangles: the eps chosen (in data units), and the next finer eps step and the
  // triangles it would give (next_triangles = 0 when the chosen mesh is already full resolution;
  // with budget_sampled, the sample's estimate: above 95% of the budget, maybe within it).
  double chosen_eps = 0;
  int chosen_eps_ties = -1;  // ExtractOptions::eps_ties of the chosen mesh (-1: every tie refined)
  double next_eps = 0;
  int next_eps_ties = -1;
  int64_t next_triangles = 0;
  // Steps (eps values, and tie classes within one) the budget search went through (remembered: the
  // first search's).
  int64_t budget_steps = 0;
  // Whether the eps came from a sample of the volume (over 257 samples on a side; docs/METHOD.md, "Focus and
  // triangle budget"): the mesh then has between 90% and 100% of the budget, and next_triangles is
  // the sample's estimate. Otherwise the choice is exact: the finest step within the budget.
  bool budget_sampled = false;
  // Whether the choice is one made before over the same open source (isotope::Source) with the
  // same isovalue, budget, error, topology mode, weight, delta and focus, taken as it was instead of
  // searched again: the same eps, the same report fields, the same mesh.
  bool budget_remembered = false;
  // With auto_delta: the delta chosen (in data units; -1 when none was), and the triangles of its
  // coarsest mesh (eps = infinity).
  double chosen_delta = -1;
  int64_t delta_floor_triangles = 0;
  // Distributed: every process's load, in rank order (on every rank); empty otherwise.
  std::vector<RankLoad> ranks;
};

// One extraction from an array in memory, with only the hierarchy the options need: at eps = 0
// (no triangle budget) none at all, since the mesh is marching tetrahedra over every cut cell;
// otherwise the hierarchy with the record fields the mode reads. The same mesh, byte for byte, as
// from a store of the same volume (isotope::Source). Throws OptionError for options out of range,
// InvalidInput for dimensions below 2 or values that are not finite, and
// TriangleBudgetTooSmall when max_triangles is below the coarsest mesh the topology mode allows,
// and ExtractionCancelled when RUN's cancel was set. RUN's progress hears the hierarchy's build.
Mesh extract(const Volume& volume, const ExtractOptions& options, const RunContext& run = {},
             ExtractStats* stats = nullptr);

}  // namespace isotope
