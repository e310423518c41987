// libFuzzer target: an NRRD header with attached data (raw or gzip), read as `isotope extract
// FILE.nrrd` and `convert` read it (the NRRD reader). Every failure must be an IoError. A detached
// data file the header names is read too: the reader refuses what is not a regular file, and the
// data's size is checked against the file before anything is allocated.
#include <filesystem>
#include <string>

#include "fuzz/fuzz_temp_file.h"
#include "io/volume/nrrd_reader.h"
#include "isotope/error.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static const isotope::fuzz::RemoveAtExit file{isotope::fuzz::temp_path(".nrrd")};
  isotope::fuzz::write_whole(file.path, data, size);
  try {
    (void)isotope::read_nrrd(file.path);
  } catch (const isotope::IoError&) {
  }
  return 0;
}
