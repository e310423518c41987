#pragma once
// eps = 0 from a volume held nowhere whole: its values are read a window of z-layers at a time
// while the windows before it are marched, so that memory holds a few windows and the mesh, and a
// cold file's reads overlap the march (docs/METHOD.md, "eps = 0 from a file"). The mesh is the one
// extract(const Volume&, ...) makes from the whole array, bit for bit, on any number of threads.
#include <array>
#include <cstdint>
#include <functional>

#include "engine/extract/options.h"
#include "isotope/extract.h"
#include "isotope/mesh.h"
#include "isotope/volume.h"

namespace isotope {

// A volume whose values are read on demand, whole z-layers at a time.
struct LayerSource {
  std::array<int64_t, 3> dims{0, 0, 0};
  std::array<double, 3> spacing{1, 1, 1};
  std::array<double, 3> origin{0, 0, 0};
  // Fills `out` with the nodes of layers [z, z + count) as float, x fastest, then y, then z. Called
  // from one thread at a time, in increasing z within a pass. Throws what the read throws (a short
  // read, a value that is not finite): the extraction throws it.
  std::function<void(int64_t z, int64_t count, float* out)> read_layers;
  // Optional: the same values without the check that they are finite. The march then checks each
  // value as it looks at it, and on one that is not reads the layers again through read_layers,
  // from the first, for its error: a volume read once, not once to check and once to march.
  std::function<void(int64_t z, int64_t count, float* out)> read_unchecked;
  // Optional: for a volume of uint8, uint16 or int16 values (`stored`), the layers as they are
  // stored, in this machine's byte order, stored-type bytes per node: what the march reads instead
  // of read_layers, converting only the values of the blocks it marches. An integer is finite.
  ScalarType stored = ScalarType::float32;
  std::function<void(int64_t z, int64_t count, unsigned char* out)> read_stored{};
};

// Whether extract_streamed makes what these options ask for: full resolution with no tie classes
// and no budget (nothing that needs the hierarchy), on a lattice with blocks. Under several
// processes (RunContext::distribution) each streams the layers of its share of the slabs.
bool streamed_extract_applies(const std::array<int64_t, 3>& dims, const ExtractOptions& options);

// The bytes of one window's values as float (a quarter of them for uint8 read as stored): one layer of blocks at least,
// more when the layers are small. At most max(2, threads + 1) windows are held, and never more than 1 GB of them unless
// two windows are larger.
int64_t streamed_window_bytes(const std::array<int64_t, 3>& dims);

// Throws as extract(const Volume&, ...) does, std::logic_error when the options need more
// than full resolution (streamed_extract_applies), and what the source's reads throw.
Mesh extract_streamed(const LayerSource& source, const ExtractCall& options, ExtractStats* stats = nullptr);

}  // namespace isotope
