#pragma once
// Lossless transform of one float array of a store brick into bytes that zstd compresses well:
// integer-valued fields (uint8/uint16 scans and their metadata) become narrow byte-shuffled
// deltas, constant fields a single value, anything else byte-shuffled bit patterns.
// The byte layout is specified in docs/FORMAT.md, "Field encoding".
#include <cstdint>
#include <span>
#include <vector>

namespace isotope {

// How a field was written: as a constant, as integers (narrow words), or as its floats' bit
// patterns (mode 3), whose low bytes are as many distinct bytes as the data has noise.
enum class FieldCoding { constant, integer, bits };

// Appends a self-describing, lossless encoding of `values` to `out` (decode restores every bit,
// incl. -0.0, +-inf, NaN payloads, denormals); returns how it was written.
FieldCoding encode_field(std::span<const float> values, std::vector<uint8_t>& out);

// Decodes one field starting at `p` into `values` (whose size the caller knows and must match the
// encoded count, else IoError); returns the pointer just past it. Never reads outside [p, end),
// never crashes on hostile bytes: throws IoError("...what is malformed...") instead.
const uint8_t* decode_field(const uint8_t* p, const uint8_t* end, std::span<float> values);
// The same for a field whose values are integers of 0..255 (a one-byte store's values:
// held_value_bytes), each into its byte, without floats in between. Returns null where some value is
// not such an integer; what was written to `bytes` then means nothing.
const uint8_t* decode_field(const uint8_t* p, const uint8_t* end, std::span<uint8_t> bytes);

}  // namespace isotope
