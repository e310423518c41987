// libFuzzer target: a TIFF stack (a multi-page file), opened as `isotope convert` opens it
// (the TIFF reader: every page's size, type and data checked at open) and read back in
// boxes. Every failure must be an IoError; memory stays bounded whatever the header claims (a page
// may not claim more values than its strips can hold).
#include <algorithm>
#include <array>
#include <filesystem>
#include <string>
#include <vector>

#include "fuzz/fuzz_temp_file.h"
#include "io/volume/tiff_reader.h"
#include "isotope/error.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static const isotope::fuzz::RemoveAtExit file{isotope::fuzz::temp_path(".tif")};
  isotope::fuzz::write_whole(file.path, data, size);
  try {
    const auto reader = isotope::open_tiff_stack(file.path);
    const std::array<int64_t, 3> dims = reader->info().dims;
    // A box as convert reads them (a tile and its halo): at most 64 nodes per axis.
    const std::array<int64_t, 3> box = {std::min<int64_t>(dims[0], 64), std::min<int64_t>(dims[1], 64),
                                        std::min<int64_t>(dims[2], 64)};
    std::vector<float> values(static_cast<size_t>(box[0] * box[1] * box[2]));
    reader->read_box({0, 0, 0}, box, values.data());
  } catch (const isotope::IoError&) {
  }
  return 0;
}
