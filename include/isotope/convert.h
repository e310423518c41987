#pragma once
// A volume on disk (or in memory) -> a store (docs/FORMAT.md): the hierarchy built band by band
// and tile by tile, its values and records in compressed, checksummed bricks, so that later
// extractions read only what they reach. Memory stays within a budget whatever the volume's size.
//
//   isotope::convert({"scan_512x512x512_uint16.raw"}, "scan.isotope");
//   isotope::Source scan = isotope::open_volume({"scan.isotope"});
#include <array>
#include <atomic>
#include <cstdint>
#include <string>

#include <isotope/distribution.h>
#include <isotope/run_context.h>
#include <isotope/source.h>
#include <isotope/store_defaults.h>
#include <isotope/volume.h>

namespace isotope {

struct ConvertOptions {
  int64_t memory_mb = 1024;            // tiles in flight and band scratch; scratch beyond a quarter of it goes to disk
  int zstd_level = 3;                  // 1 .. 19
  int brick_bits = kDefaultBrickBits;  // bricks of 2^B nodes per axis, B in 3 .. 6
  // 0: values as read (lossless). 8 or 16: float values as codes 0 .. 2^bits-1 over the data
  // range; the hierarchy is built on the codes, and half a code step, the rounding error, is
  // added to every error indicator (docs/FORMAT.md, "Quantization").
  int quantize_bits = 0;
};

struct ConvertStats {
  std::array<int64_t, 3> dims{0, 0, 0};
  std::string type;  // the input's element type, as the store's header keeps it
  double seconds = 0;
  uint64_t input_bytes = 0;   // element data of the input
  uint64_t output_bytes = 0;  // the store file
  int64_t bricks = 0;
  int tiles_in_flight = 0;
  int bands_built_beside = 0;  // in one pass with the band before them, where their hand-over would have been a file
  uint64_t input_held_bytes =
      0;  // the input read once and held whole, where a quarter of the budget took it; 0: read by tiles
};

// Writes OUTPUT atomically (temporary name, renamed when complete): on any error or cancellation
// nothing is left behind, and an OUTPUT that is the input, a device, a FIFO or a directory is
// refused before any work. The file does not depend on the thread count or the memory budget.
// Scratch data goes to unlinked files beside OUTPUT. Throws IoError, and OptionError for options
// out of range (or --quantize on integer data). RUN: a cancel flag set stops it with
// IoError("interrupted") and no file left; its progress hears the build; under a distribution, each
// process builds a contiguous share of band 0's tiles and rank 0 the coarser bands from what they
// hand on, the same file byte for byte (OUTPUT's directory must be one every process sees).
ConvertStats convert(const VolumeSpec& input, const std::string& output, const ConvertOptions& options = {},
                     const RunContext& run = {});
// The same from an array in memory.
ConvertStats convert(const Volume& volume, const std::string& output, const ConvertOptions& options = {},
                     const RunContext& run = {});

}  // namespace isotope
