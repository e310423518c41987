#pragma once
// Adaptive isosurface extraction over the bisection hierarchy (paper Sec. 3.2 with the stopping
// rule of docs/METHOD.md), and the full-resolution baseline it must equal at eps = 0. The
// extraction from an array, extract(const Volume&, ...), is public (isotope/extract.h).
#include <cstdint>

#include "engine/core/volume_check.h"        // validate_volume: what extract(const Volume&) refuses
#include "engine/extract/full_resolution.h"  // the baseline, offered with the extraction it checks
#include "engine/extract/options.h"
#include "engine/hierarchy/multires_volume.h"
#include "isotope/extract.h"
#include "isotope/mesh.h"
#include "isotope/volume.h"

namespace isotope {

// Throws as extract(const Volume&, ...) does (isotope/extract.h).
Mesh extract(const MultiresVolume& mv, const ExtractCall& options, ExtractStats* stats = nullptr);

class BudgetMemo;
class Hierarchy;
// extract() over an in-memory hierarchy. Throws InvalidInput when the options read a field
// the hierarchy was built without. `memo`: as extract_adaptive's (a budget's choice remembered),
// for a hierarchy kept open.
Mesh extract(const Hierarchy& hierarchy, const ExtractCall& options, ExtractStats* stats = nullptr,
             BudgetMemo* memo = nullptr);

// extract(volume, options, stats) for a volume validate_volume() accepted before, whose values
// cannot have changed since (not a borrowed array): they are not scanned again.
Mesh extract_validated(const Volume& volume, const ExtractCall& options, ExtractStats* stats = nullptr,
                       const ProgressCallback& progress = {});

// Whether extract(volume, options) needs a hierarchy (eps > 0, tie classes at eps 0, or a
// triangle budget): all but full resolution.
bool needs_hierarchy(const ExtractOptions& options);

// Whether the options' triangle budget takes the full-resolution mesh of `volume`: it fits the
// budget (count_full_resolution_triangles), so it is the finest mesh that does, the search's
// choice, found without the hierarchy the search would build (docs/METHOD.md, "Focus and triangle
// budget"). Only for a budget alone: one that chooses delta too (auto_delta), or spread over
// processes, searches as before. Throws OptionError for options validate() refuses.
bool budget_takes_full_resolution(const Volume& volume, const ExtractCall& options);

}  // namespace isotope
