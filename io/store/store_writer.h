#pragma once
// `isotope convert`: a volume on disk -> a store (docs/FORMAT.md), band by band and tile by
// tile (docs/METHOD.md, "Per-vertex records"), so that memory stays within a budget whatever the volume's size.
#include <atomic>
#include <cstdint>
#include <string>

#include "engine/hierarchy/store_layout.h"
#include "io/store/store_format.h"
#include "io/volume/box_reader.h"
#include "isotope/convert.h"
#include "isotope/run_context.h"

namespace isotope {

// Whether a store outlives the process that writes it: durable once convert returns (fsynced,
// its bricks written past the page cache), or read back and removed by that process (a volume's
// hierarchy store, docs/METHOD.md "One-shot extraction through a store"): through the page cache
// and never synced, the same bytes.
enum class StoreLife { kept, transient };

// One convert as the store's writer carries it: the store's settings and the run context they run
// under (isotope/run_context.h), held whole (the threads are the entry point's to apply; a cancel
// gives IoError("interrupted") at the next tile). From options alone: this process alone, never
// cancelled, heard by no one.
struct ConvertCall : ConvertOptions, RunContext {
  ConvertCall() = default;
  ConvertCall(const ConvertOptions& options, const RunContext& run = {})  // NOLINT: options alone convert
      : ConvertOptions(options), RunContext(run) {}
};

// Writes OUTPUT atomically (temporary name, renamed when complete); on any error or
// cancellation nothing is left behind. Throws IoError.
// SECTIONS: those its bricks hold (docs/FORMAT.md, "Sections"): every one (kAllSections, what
// `isotope convert` writes), or those its extractions read (sections_for): a volume's hierarchy
// store, whose records' fields that no section holds are then not computed either: their topology
// without the exact, weights and extra sections (a quarter of embryo's build), their
// simplification weights without the weights section (a seventh). A brick's sections left out are
// 0 bytes, and an extraction that reads one stops at "a section is missing". Not under a
// distribution, whose stores are kept.
ConvertStats convert_to_store(const BoxReader& input, const std::string& output, const ConvertCall& options,
                              StoreLife life = StoreLife::kept, const StoreSections& sections = kAllSections);

}  // namespace isotope
