#include "io/store/held_words.h"

#include <algorithm>
#include <bit>
#include <cstring>

namespace isotope {

// What the header promises of every value: codes of 8 or 16 bits, or a lossless scan of unsigned
// integers within the range it gives.
int held_value_bytes(const StoreHeader& h) {
  if (h.quantize_bits != 0) return h.quantize_bits <= 8 ? 1 : 2;
  if (h.source_type != "uint8" && h.source_type != "uint16") return 4;
  return h.value_min >= 0 && h.value_max <= 255 ? 1 : h.value_min >= 0 && h.value_max <= 65535 ? 2 : 4;
}

std::string value_not_held(const StoreHeader& h) {
  return "holds a value that is not " + (h.quantize_bits != 0
                                             ? "a " + std::to_string(h.quantize_bits) + "-bit code"
                                             : "an integer of the header's " + h.source_type + " range");
}

// The fewest bytes (1, 2 or 4) that hold every value exactly. On the bits, branch-free, so that
// it vectorizes: every brick read is checked. A non-negative float orders as its bits do; a
// negative one (-0 too) or a NaN has bits above those of 65535 and clamps to it. The integer's
// float must then be v's very bits: that rejects negatives, -0, NaN, fractions and what the clamp
// moved.
int fewest_bytes(std::span<const float> values) {
  constexpr uint32_t k65535 = std::bit_cast<uint32_t>(65535.0f);
  uint32_t not_short = 0, not_byte = 0;
  for (const float v : values) {
    const auto bits = std::bit_cast<uint32_t>(v);
    const auto k = static_cast<int32_t>(std::bit_cast<float>(std::min(bits, k65535)));
    not_short |= std::bit_cast<uint32_t>(static_cast<float>(k)) ^ bits;
    not_byte |= static_cast<uint32_t>(k) & ~0xffu;
  }
  return not_short != 0 ? 4 : not_byte != 0 ? 2 : 1;
}

bool narrow_bounds(const uint64_t* words, size_t n, uint32_t* narrow) {
  static_assert(std::endian::native == std::endian::little, "a word's halves are copied as little-endian");
  // Branch-free over 32-bit lanes, so that it vectorizes: verify runs every brick of stored records
  // of a uint8 store through it (the words are copied as halves first: a loop that splits 64-bit
  // loads does not vectorize).
  constexpr size_t kBlock = 512;
  uint32_t bad = 0;
  for (size_t first = 0; first < n; first += kBlock) {
    const size_t count = std::min(kBlock, n - first);
    uint32_t half[2 * kBlock];  // little-endian: the low half (lo, hi), then the bound's bits
    std::memcpy(half, words + first, count * sizeof(uint64_t));
    uint32_t* out = narrow + first;
    for (size_t i = 0; i < count; ++i) out[i] = narrow_word_of(half[2 * i], half[2 * i + 1], bad);
  }
  return bad == 0;
}

}  // namespace isotope
