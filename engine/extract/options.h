#pragma once
// The engine's side of the extraction options (isotope/extract.h): which record fields an
// extraction reads, and the cancellation check its loops make.
#include "isotope/extract.h"

namespace isotope {

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

// Throws ExtractionCancelled when `options` asks to stop; cheap enough for every piece or slab.
inline void throw_if_cancelled(const ExtractOptions& options) {
  if (options.cancel && options.cancel->load(std::memory_order_relaxed)) throw ExtractionCancelled{};
}

}  // namespace isotope
