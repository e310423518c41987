#pragma once
// `isotope convert`: a volume on disk -> a store (docs/FORMAT.md), band by band and tile by
// tile (engine/hierarchy/band_tile.h), so that memory stays within a budget whatever the volume's size.
#include <atomic>
#include <cstdint>
#include <string>

#include "engine/hierarchy/store_layout.h"
#include "io/volume/box_reader.h"
#include "isotope/convert.h"

namespace isotope {

// Whether a store outlives the process that writes it: durable once convert returns (fsynced,
// its bricks written past the page cache), or read back and removed by that process (a volume's
// hierarchy store, docs/METHOD.md "One-shot extraction through a store"): through the page cache
// and never synced, the same bytes.
enum class StoreLife { kept, transient };

// What a store's records hold: every field a mode reads (what `isotope convert` writes), or the
// core alone, their range and error bound (docs/FORMAT.md, "Sections"): for a volume's hierarchy
// store whose extractions all read no more (mode none with the bound error, sections_for), whose
// records' topology is then neither computed nor written (a quarter of embryo's build). The
// bricks of such a store have their core section only, and an extraction that reads another
// stops at "a section is missing". Not under a distribution, whose stores are kept.
enum class StoreRecords { all, core };

// Writes OUTPUT atomically (temporary name, renamed when complete); on any error or
// cancellation nothing is left behind. Throws IoError.
ConvertStats convert_to_store(const BoxReader& input, const std::string& output, const ConvertOptions& options,
                              StoreLife life = StoreLife::kept, StoreRecords records = StoreRecords::all);

}  // namespace isotope
