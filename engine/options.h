#pragma once
// What a user chooses for one extraction.
#include <array>
#include <atomic>
#include <cstdint>
#include <exception>
#include <optional>
#include <string_view>

namespace isotope {

// Which saturated error a tetrahedron's refinement vertex is judged by (design.md).
enum class ErrorIndicator {
  bound,    // guaranteed L-infinity deviation of the coarse interpolant from the data (default)
  surplus,  // the paper's |f(v) - (f(a)+f(b))/2|, saturated by max
};

enum class TopologyMode {
  none,      // refine by error only (paper Sec. 3)
  paper,     // the paper's critical points and intervals (Sec. 4.2-4.4), faithfully
  preserve,  // the exact local rule of design.md: keeps components and Euler characteristic
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

struct ExtractOptions {
  float iso = 0.0f;           // inside means value > iso
  double eps = 0.0;           // refine while the chosen error is >= eps; 0 gives full resolution
  ErrorIndicator error = ErrorIndicator::bound;
  TopologyMode topology = TopologyMode::preserve;
  SimplificationWeight weight = SimplificationWeight::interval;  // simplify mode only
  double delta = 0.0;         // simplify mode: critical points of weight < delta may be dropped
  std::optional<Focus> focus;
  // > 0: ignore eps and take the finest eps whose mesh has at most this many triangles.
  int64_t max_triangles = 0;
  // With max_triangles in simplify mode: choose delta too (engine/adaptive_extract.h): the smallest
  // delta whose coarsest mesh takes at most half the budget (features of smallest weight dropped
  // first), then the finest eps within the whole budget. delta must be 0.
  bool auto_delta = false;
  // Set (by another thread) to stop: the extraction then throws ExtractionCancelled at its next
  // piece or slab. For a server whose client asked for something newer; nullptr: never.
  const std::atomic<bool>* cancel = nullptr;
};

// Which fields of the records a hierarchy holds, or an extraction reads, beyond the range and the
// guaranteed error bound that every visit reads: `preserve` reads the exact critical intervals,
// `simplify` those and the weights, `paper` the paper's intervals, --error surplus the paper's
// surplus.
struct RecordFields {
  bool exact = true, paper = true, weights = true, surplus = true;
  bool covers(const RecordFields& o) const {
    return (exact || !o.exact) && (paper || !o.paper) && (weights || !o.weights) && (surplus || !o.surplus);
  }
  bool topology() const { return exact || paper || weights; }
  RecordFields operator|(const RecordFields& o) const {
    return {exact || o.exact, paper || o.paper, weights || o.weights, surplus || o.surplus};
  }
};
// What an extraction with these options reads (at eps 0 nothing: no tetrahedron stops above the
// leaves, so no topology is ever asked).
RecordFields fields_for(const ExtractOptions& options);

// What an extraction throws when its ExtractOptions::cancel was set.
struct ExtractionCancelled : std::exception {
  const char* what() const noexcept override { return "extraction cancelled"; }
};
// Throws ExtractionCancelled when `options` asks to stop; cheap enough for every piece or slab.
inline void throw_if_cancelled(const ExtractOptions& options) {
  if (options.cancel && options.cancel->load(std::memory_order_relaxed)) throw ExtractionCancelled{};
}

std::string_view to_string(ErrorIndicator e);
std::string_view to_string(TopologyMode t);
std::optional<ErrorIndicator> parse_error_indicator(std::string_view s);
std::optional<TopologyMode> parse_topology_mode(std::string_view s);
std::string_view to_string(SimplificationWeight w);
std::optional<SimplificationWeight> parse_simplification_weight(std::string_view s);

}  // namespace isotope
