#pragma once
// The optional fields of the records, as the build computes them, a store keeps them and an
// extraction reads them (fields_for, from the extraction options).

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

}  // namespace isotope
