#pragma once
#include <atomic>

// The engine's side of the extraction options (isotope/extract.h): which record fields an
// extraction reads (RecordFields), and the cancellation check its loops make.
#include "engine/hierarchy/record_fields.h"
#include "isotope/extract.h"
#include "isotope/run_context.h"

namespace isotope {

// What an extraction with these options reads (at eps 0 nothing: no tetrahedron stops above the
// leaves, so no topology is ever asked).
RecordFields fields_for(const ExtractOptions& options);

// A threshold (eps, delta) given in the data's units, as the codes of a quantized store are
// compared with it (`factor`: what one code is worth in those units), and a threshold in codes as
// it is reported. A key c reported as c * factor and read back as a plain quotient can come back
// an ulp off c, and then the cut a budget chose is lost: the key is no longer >= eps, or its tie
// classes (which need key == eps) no longer apply. A key is mostly a float error plus the
// rounding of quantization, a few dozen significant bits, where its neighbours have 53: so of the
// doubles x whose product x * factor rounds to the value given, one with at least 16 more trailing
// zero bits than the quotient replaces it. Keys with arbitrary low bits (under a focus) and
// values no code's product gives (typed by hand) keep the plain quotient.
double threshold_in_codes(double value, double factor);
inline double threshold_in_data(double codes, double factor) { return codes * factor; }

// One extraction as the engine carries it through its passes: the method's settings and the run
// context they run under (isotope/run_context.h), held whole so that a field the context gains
// reaches every pass (the threads and the progress are the entry point's to apply). From options
// alone: this process alone, never cancelled.
struct ExtractCall : ExtractOptions, RunContext {
  ExtractCall() = default;
  ExtractCall(const ExtractOptions& options, const RunContext& run = {})  // NOLINT: options alone convert
      : ExtractOptions(options), RunContext(run) {}
  // Both halves, each in the words every face uses.
  void validate() const {
    ExtractOptions::validate();
    RunContext::validate();
  }
};

// Throws ExtractionCancelled when `options` asks to stop; cheap enough for every piece or slab.
inline void throw_if_cancelled(const ExtractCall& options) {
  if (options.cancel && options.cancel->load(std::memory_order_relaxed)) throw ExtractionCancelled{};
}

}  // namespace isotope
