#pragma once
// `isotope convert`: a volume on disk -> a store (docs/FORMAT.md), band by band and tile by
// tile (engine/band_tile.h), so that memory stays within a budget whatever the volume's size.
#include <atomic>
#include <cstdint>
#include <string>

#include "engine/progress.h"
#include "engine/store_layout.h"
#include "io/box_reader.h"

namespace isotope {

struct ConvertOptions {
  int64_t memory_mb = 1024;  // tiles in flight and band scratch; scratch beyond a quarter of it goes to disk
  int zstd_level = 3;
  int brick_bits = StoreLayout::kDefaultBrickBits;
  // 0: values as read (lossless). 8 or 16: float values as codes 0 .. 2^bits-1 over the data
  // range; the hierarchy is built on the codes, and half a code step, the rounding error, is
  // added to every error indicator (docs/FORMAT.md, "Quantization").
  int quantize_bits = 0;
  ProgressCallback progress;
  const std::atomic<bool>* cancel = nullptr;  // set (e.g. by SIGINT) to stop; IoError("interrupted")
};

struct ConvertStats {
  double seconds = 0;
  uint64_t input_bytes = 0;   // element data of the input
  uint64_t output_bytes = 0;  // the store file
  int64_t bricks = 0;
  int tiles_in_flight = 0;
};

// Writes OUTPUT atomically (temporary name, renamed when complete); on any error or
// cancellation nothing is left behind. Throws IoError.
ConvertStats convert_to_store(const BoxReader& input, const std::string& output, const ConvertOptions& options);

}  // namespace isotope
