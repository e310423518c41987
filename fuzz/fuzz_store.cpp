// libFuzzer target: a store file (docs/FORMAT.md) through the reads `isotope extract` takes (the
// header and directories opened by StoreReader, bricks paged by the extraction at eps 0 and at a
// coarse eps with topology simplification, which reads every section) and through `isotope verify`.
// Every failure must be an IoError; anything else (a crash, a sanitizer report, another exception,
// a hang or a large allocation) is a finding.
//
// The first byte of the input chooses how the rest is read: even, as it is (the checksums catch
// most edits); odd, with every checksum the format has recomputed over the edited bytes first
// (header, band directories, brick sections), so that edits reach the checks behind the checksums:
// field ranges, directory bounds and overlaps, zstd frames, the decoded fields.
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "engine/extract/options.h"
#include "fuzz/fuzz_temp_file.h"
#include "io/store/brick_cache.h"
#include "io/store/paged_volume.h"
#include "io/store/store_format.h"
#include "io/store/store_reader.h"
#include "isotope/error.h"

namespace {

using namespace isotope;

uint64_t load_u64(const std::vector<uint8_t>& b, size_t at) {
  uint64_t v = 0;
  if (at + 8 <= b.size()) std::memcpy(&v, b.data() + at, 8);
  return v;
}
uint32_t load_u32(const std::vector<uint8_t>& b, size_t at) {
  uint32_t v = 0;
  if (at + 4 <= b.size()) std::memcpy(&v, b.data() + at, 4);
  return v;
}
void store_u64(std::vector<uint8_t>& b, size_t at, uint64_t v) {
  if (at + 8 <= b.size()) std::memcpy(b.data() + at, &v, 8);
}

// Recomputes the checksums wherever the (possibly edited) fields point inside the file.
void reseal(std::vector<uint8_t>& b) {
  if (b.size() < kHeaderBytes) return;
  for (int j = 0; j < kMaxBands; ++j) {
    const size_t row = kBandTableAt + static_cast<size_t>(j) * 24;
    const uint64_t offset = load_u64(b, row), bytes = load_u64(b, row + 8);
    if (bytes == 0 || offset > b.size() || bytes > b.size() - offset) continue;
    for (uint64_t e = 0; e + kEntryBytes <= bytes; e += kEntryBytes) {
      uint64_t at = load_u64(b, offset + e);
      for (int s = 0; s < kSections; ++s) {
        const uint32_t size = load_u32(b, offset + e + 8 + static_cast<size_t>(s) * 4);
        if (size > kChecksumBytes && at <= b.size() && size <= b.size() - at)
          store_u64(b, at, store_checksum(b.data() + at + kChecksumBytes, size - kChecksumBytes));
        at += size;
      }
    }
    store_u64(b, row + 16, store_checksum(b.data() + offset, bytes));
  }
  store_u64(b, kHeaderChecksumAt, store_checksum(b.data(), kHeaderChecksumAt));
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static const fuzz::RemoveAtExit file{fuzz::temp_path(".isotope")};
  if (size < 1) return 0;
  std::vector<uint8_t> bytes(data + 1, data + size);
  if ((data[0] & 1) != 0) reseal(bytes);
  fuzz::write_whole(file.path, bytes.data(), bytes.size());
  try {
    const StoreReader store(file.path);
    BrickCache cache(store, 16 << 20);
    const PagedVolume volume(cache);
    const StoreHeader& h = store.header();
    ExtractOptions options;
    options.iso = static_cast<float>(0.5 * (h.value_min + h.value_max));
    (void)extract(volume, options);  // eps 0, preserve: values and band 0's records
    options.eps = 0.25 * (h.value_max - h.value_min);
    options.topology = TopologyMode::simplify;
    options.delta = 0.1 * (h.value_max - h.value_min);
    (void)extract(volume, options);  // coarse: the stored records, every section
  } catch (const IoError&) {
  }
  try {
    (void)verify_store(file.path);
  } catch (const IoError&) {
  }
  return 0;
}
