#pragma once
// What every consumer of an array in memory refuses: dimensions outside 2 .. 2^19 + 1 per axis
// (the traversal packs coordinates in 21 bits), values that do not fill them, values that are not
// finite. One check for the one-shot extraction, the hierarchy's build, the exact reference build,
// isotope::open_volume and isotope::convert.
#include "isotope/volume.h"

namespace isotope {

// Throws std::invalid_argument naming the first problem.
void validate_volume(const Volume& volume);

}  // namespace isotope
