#pragma once
// The .isotope store, version 4 (docs/FORMAT.md): a 1024-byte header with a table of band
// directories, the bricks, then one directory per band. A brick is up to four sections, each a
// checksummed zstd frame, so that an extraction reads and decodes only the fields its mode needs:
// core (values; range and bound of the records), exact intervals, weights, and extra (the paper's
// intervals and surplus). Everything little-endian, offsets 64-bit. This file turns those bytes
// into structs and back and checks them; it never touches a file.
#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "engine/hierarchy/hierarchy.h"
#include "engine/hierarchy/store_layout.h"

namespace isotope {

inline constexpr std::array<char, 8> kStoreMagic = {'I', 'S', 'O', 'S', 'T', 'O', 'R', 'E'};
// 2: three simplification weights per record; 3: compact records in sections, band directories;
// 4: diamonds reaching past the data box hold the clamped field's errors, not infinity.
inline constexpr uint32_t kStoreVersion = 4;
inline constexpr size_t kHeaderBytes = 1024;
inline constexpr size_t kEntryBytes = 24;
inline constexpr size_t kBandTableAt = 256;                    // the header's table of band directories
inline constexpr size_t kHeaderChecksumAt = kHeaderBytes - 8;  // XXH64 of the header's bytes before it
inline constexpr size_t kChecksumBytes = 8;                    // each section starts with the XXH64 of its frame
inline constexpr int kMaxBands = 20;                           // k <= 19: dims up to 2^19 + 1
inline constexpr int kMinBrickBits = 3, kMaxBrickBits = 6;

// A brick's sections, in file order.
enum class Section : int { core = 0, exact = 1, weights = 2, extra = 3 };
inline constexpr int kSections = 4;
// A set of a brick's sections, by Section: those a read takes, or those a store holds (every one,
// kAllSections, but for a volume's hierarchy store: convert_to_store's `sections`).
using StoreSections = std::array<bool, kSections>;
inline constexpr StoreSections kAllSections{true, true, true, true};
// Which sections an extraction reading these fields needs besides the core.
StoreSections sections_for(const RecordFields& f);
// Whether bricks of these sections hold a field of their records' topology (any but the core's).
inline bool with_topology(const StoreSections& sections) { return sections[1] || sections[2] || sections[3]; }

struct BandDirectory {
  uint64_t offset = 0, bytes = 0, checksum = 0;  // XXH64 (seed 0) of the directory's bytes
};

struct StoreHeader {
  std::array<int64_t, 3> dims{0, 0, 0};
  std::array<double, 3> spacing{1, 1, 1};
  std::array<double, 3> origin{0, 0, 0};
  int brick_bits = kDefaultBrickBits;
  int lattice_k = 0;        // redundant with dims, checked
  std::string source_type;  // element type of the input, e.g. "uint16" (at most 15 chars)
  double value_min = 0, value_max = 0;
  int64_t brick_count = 0;
  std::array<int64_t, 3> critical_paper{0, 0, 0}, critical_exact{0, 0, 0};
  uint64_t input_bytes = 0;  // size of the input's element data, for the ratio
  int zstd_level = 0;
  int quantize_bits = 0;  // 0: lossless; else values are codes, value = offset + scale * code
  double value_offset = 0, value_scale = 1;
  std::array<BandDirectory, kMaxBands> bands{};
};

// Half a code step in code units: the rounding of a quantized store's values, which its records
// (those of the quantized field) do not include; the traversal adds it to every error it compares
// with eps (SplitRule), so eps still bounds the deviation from the data.
inline constexpr float kQuantizationError = 0.5f;

struct BrickEntry {
  uint64_t offset = 0;                      // of the first section
  std::array<uint32_t, kSections> bytes{};  // each section's size, 0: none
  uint64_t section_offset(Section s) const {
    uint64_t at = offset;
    for (int i = 0; i < static_cast<int>(s); ++i) at += bytes[static_cast<size_t>(i)];
    return at;
  }
  uint64_t total() const { return uint64_t{bytes[0]} + bytes[1] + bytes[2] + bytes[3]; }
};

uint64_t store_checksum(const void* data, size_t bytes);

std::array<uint8_t, kHeaderBytes> encode_header(const StoreHeader& h);
// Throws IoError naming `file`: wrong magic, unsupported version (an older one: "convert the volume
// again"), checksum mismatch, fields out of their range or contradicting each other.
StoreHeader decode_header(const uint8_t* bytes, size_t size, const std::string& file);

std::vector<uint8_t> encode_directory(const std::vector<BrickEntry>& entries);
// Checks a band's directory read straight into its entries (an entry's 24 bytes are its fields in
// order, little-endian as the host), which spares a copy of the bytes: a 2048^3 volume's band 0
// has 2 M entries, 50 MB. `grid`: the band's bricks per axis, the entries x fastest. Throws
// IoError naming `file` when the checksum or an entry is wrong: an entry outside
// [kHeaderBytes, area_end), a section with no room, or bricks that do not tile one run of the file.
// Throws std::logic_error when `entries` are not the grid's bricks (a caller's error, not a file's).
void check_directory(std::span<const BrickEntry> entries, const Box3& grid, const BandDirectory& d, uint64_t area_end,
                     const std::string& file);

// Whether band j's bricks have records (bands 1 .. k-1 store them; band 0's are rebuilt from its
// values, the corners of band k have none).
inline bool stores_records(const StoreLayout& layout, int j) { return j >= 1 && j < layout.lattice().k; }

// A brick's fields as the encoder takes them: the values (T^3, Morton order) and, for bands that
// store records, each record field over the record slots (7/8 T^3, Morton order), as the floats
// their codes stand for (docs/FORMAT.md, "Compact records").
struct BrickFields {
  enum Record { lo, hi, bound, exact_lo, exact_hi, w0, w1, w2, paper_lo, paper_hi, surplus, count };
  std::vector<float> values;
  std::array<std::vector<float>, count> records;
};
// The fields of a filled brick (a BrickView with every field present).
BrickFields fields_of(const StoreLayout& layout, int band, const BrickView& brick);

// The sections of a brick, each ready to be written: an XXH64 of the zstd frame, then the frame.
// Sections the band does not store are empty, and so are those `which` leaves out (a volume's
// hierarchy store of some sections: convert_to_store, StoreSections), whose fields `brick`
// need not hold.
std::array<std::vector<uint8_t>, kSections> encode_brick(const StoreLayout& layout, int band, const BrickFields& brick,
                                                         int zstd_level, const StoreSections& which = kAllSections);

// Checks a section's checksum, inflates it and decodes its fields into the brick's arrays (those
// the section holds must be present). Throws IoError starting with `where` ("FILE: brick 12 (band
// 0, brick 1 0 0)") naming what is wrong.
// `narrow`: a one-byte store's brick (held_value_bytes 1), whose values go straight into bytes
// and whose core records into 32-bit words instead (`values` and out.bounds are then not written).
// A value that is not a byte throws IoError "WHERE: " + value_not_held + " (corrupt brick)", a
// record the words cannot hold "WHERE: " + kRecordNotHeld + " (corrupt brick)". Of a band that
// stores no records (band 0, the top), no word is written: the caller fills them.
struct NarrowBrick {
  uint8_t* values = nullptr;
  uint32_t* words = nullptr;
  std::string_view value_not_held;  // what the header promised a value to be, refused
};
void decode_section(const StoreLayout& layout, int band, Section s, const uint8_t* bytes, size_t size,
                    const BrickView& out, float* values, const std::string& where, const NarrowBrick* narrow = nullptr);

}  // namespace isotope
