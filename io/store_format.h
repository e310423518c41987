#pragma once
// The .isotope store, version 2 (docs/FORMAT.md): a 512-byte header, the bricks, and a directory
// with one 72-byte entry per brick. Everything little-endian, offsets 64-bit. This file turns
// those bytes into structs and back and checks them; it never touches a file.
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "engine/record.h"
#include "engine/store_layout.h"

namespace isotope {

inline constexpr std::array<char, 8> kStoreMagic = {'I', 'S', 'O', 'S', 'T', 'O', 'R', 'E'};
inline constexpr uint32_t kStoreVersion = 2;  // 2: three simplification weights per record
inline constexpr size_t kHeaderBytes = 512;
inline constexpr size_t kEntryBytes = 72;
inline constexpr int kBrickFields = 12;  // values, then the eleven record fields

struct StoreHeader {
  std::array<int64_t, 3> dims{0, 0, 0};
  std::array<double, 3> spacing{1, 1, 1};
  std::array<double, 3> origin{0, 0, 0};
  int brick_bits = StoreLayout::kDefaultBrickBits;
  int lattice_k = 0;                 // redundant with dims, checked
  std::string source_type;           // element type of the input, e.g. "uint16" (at most 15 chars)
  double value_min = 0, value_max = 0;
  int64_t brick_count = 0;
  uint64_t directory_offset = 0, directory_bytes = 0, directory_checksum = 0;
  std::array<int64_t, 3> critical_paper{0, 0, 0}, critical_exact{0, 0, 0};
  uint64_t input_bytes = 0;          // size of the input's element data, for the ratio
  int zstd_level = 0;
  int quantize_bits = 0;             // 0: lossless; else values are codes, value = offset + scale * code
  double value_offset = 0, value_scale = 1;
};

// Half a code step in code units: what quantization adds to every finite error of a record.
inline constexpr float kQuantizationError = 0.5f;

// Per brick, what lets a traversal skip it unread: hull of the value ranges of its records and
// values, the largest errors, hulls of the critical intervals, the largest weights.
struct BrickSummary {
  float lo = 0, hi = 0, max_error_bound = 0, max_error_surplus = 0;
  float exact_lo = 1, exact_hi = 0, paper_lo = 1, paper_hi = 0;
  std::array<float, 3> max_weight{0, 0, 0};
};

struct BrickEntry {
  uint64_t offset = 0;
  uint32_t compressed_bytes = 0, raw_bytes = 0;
  uint64_t checksum = 0;  // XXH64 (seed 0) of the compressed bytes
  BrickSummary summary;
};

// A brick's contents: the values of its T^3 nodes in Morton order, then the records of its nodes
// of scale exactly j (Morton code not a multiple of 8) in Morton order. Nodes beyond the band's
// grid, and records beyond record_extent, are zero.
inline constexpr Record kAbsentRecord{DiamondBounds{0, 0, 0, 0}, DiamondTopology{0, 0, 0, 0, {0, 0, 0}}};

struct BrickContents {
  std::vector<float> values;
  std::vector<Record> records;
};

uint64_t store_checksum(const void* data, size_t bytes);

std::array<uint8_t, kHeaderBytes> encode_header(const StoreHeader& h);
// Throws IoError naming `file`: wrong magic, unsupported version, checksum mismatch, fields
// that contradict each other (dims vs k, brick count vs layout).
StoreHeader decode_header(const uint8_t* bytes, size_t size, const std::string& file);

std::vector<uint8_t> encode_directory(const std::vector<BrickEntry>& entries);
// Throws IoError naming `file` when the size or checksum is wrong.
std::vector<BrickEntry> decode_directory(const uint8_t* bytes, size_t size, const StoreHeader& h,
                                         const std::string& file);

BrickSummary summarize_brick(const BrickContents& brick);

// The stored fields of a brick: its values, then the nine record fields (none for band 0, see
// io/store_brick.h). Fills entry.{compressed_bytes, raw_bytes, checksum}; the caller sets the
// offset and the summary.
std::vector<uint8_t> encode_brick(const std::vector<float>& values, const std::vector<Record>& records,
                                  int zstd_level, BrickEntry& entry);
// Checks the checksum, inflates, decodes into arrays already sized as the band requires. Throws
// IoError starting with `where` ("FILE: brick 12 (band 0, brick 1 0 0)") naming what is wrong.
void decode_brick(const uint8_t* compressed, const BrickEntry& entry, std::vector<float>& values,
                  std::vector<Record>& records, const std::string& where);



}  // namespace isotope
