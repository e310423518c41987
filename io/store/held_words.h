#pragma once
// The widths a store's words are held in, as its header promises them (docs/METHOD.md, "Out of
// core"): a store of integers of 0..255 (a uint8 scan, 8-bit codes) holds a value in a byte and a
// record's range and bound in 32 bits, one of integers up to 65535 a value in two bytes. What the
// cache (BrickCache) holds them in, and what verify (verify_store) checks
// every brick against, so that a brick the extraction refuses as corrupt is refused by verify too.
// (The cache decodes a one-byte store's records straight into narrow words, decode_section's
// `narrow`, which takes and refuses what narrow_bounds does: a test holds the two together.)
#include <algorithm>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <span>
#include <string>

#include "engine/hierarchy/record.h"
#include "io/store/store_format.h"

namespace isotope {

// Bytes a value of this store's bricks is held in (BrickValues): 1 or 2 where the header says
// every value is an integer of 0..255 or 0..65535 (its codes, or an unsigned integer type and its
// range), else 4.
int held_value_bytes(const StoreHeader& header);

// The fewest bytes (1, 2 or 4) that hold every value exactly.
int fewest_bytes(std::span<const float> values);
// What a brick holds that its header's widths cannot, in a corrupt brick's message.
std::string value_not_held(const StoreHeader& header);
inline constexpr const char* kRecordNotHeld =
    "holds a record whose range is not of integers of 0..255 in order, or whose bound is not a multiple of a half "
    "up to 32767 nor +inf";

// A record's range and bound as the cache holds them where values are held in one byte: in 32
// bits instead of the 64 of a compact record's word (bounds_word). A record's lo and hi are
// then integers of 0..255, a byte each; its bound is a multiple of a half (at each level, the
// distance of the value at a diamond's centre from the mean of the values at its edge's ends,
// added over at most 3k <= 57 levels: at most 14,535), kept as a count of halves in 16 bits, or
// 0xffff for +inf (no record of a store holds it, but the code is kept for one that would). A uint8
// brick then takes 5 bytes a node with its values instead of 9: 5/9 of the memory a coarse
// extraction touches fresh, and 1.8 times the bricks within a cache's budget (docs/METHOD.md,
// "Out of core"). Exact both ways: a word reads back as the very 64-bit word it came from.
inline constexpr uint32_t kUnsetNarrowBounds = 0x00ffu;  // lo 255 above hi 0: the range of no record
// Bytes a record's range-and-bound word is held in: 4 beside values held in one byte, else 8.
inline int held_bounds_bytes(int value_bytes) { return value_bytes == 1 ? 4 : 8; }
// A narrow word's fields from a record's float bits, branch-free so that loops over records
// vectorize; `bad` gains nonzero bits where a field has no narrow form. Each is clamped on its bits
// (a non-negative float orders as its bits do; a negative one, or a NaN, clamps to the top),
// narrowed, and must come back as its very bits: that rejects NaN, negatives, -0, fractions, a
// bound between halves, and what the clamps moved.
// A range's end: its byte, an integer of 0..255.
inline uint32_t narrow_code(uint32_t bits, uint32_t& bad) {
  constexpr uint32_t k255 = std::bit_cast<uint32_t>(255.0f);
  const auto code = static_cast<int32_t>(std::bit_cast<float>(std::min(bits, k255)));
  bad |= std::bit_cast<uint32_t>(static_cast<float>(code)) ^ bits;
  return static_cast<uint32_t>(code);
}
// A bound: its count of halves, up to 32767, or 0xffff for +inf, in the word's top 16 bits.
inline uint32_t narrow_bound(uint32_t bits, uint32_t& bad) {
  constexpr uint32_t k32767 = std::bit_cast<uint32_t>(32767.0f);
  const auto halves = static_cast<int32_t>(2 * std::bit_cast<float>(std::min(bits, k32767)));
  const uint32_t infinite = 0u - static_cast<uint32_t>(bits == 0x7f800000u);
  bad |= ~infinite & (std::bit_cast<uint32_t>(0.5f * static_cast<float>(halves)) ^ bits);
  return static_cast<uint32_t>(halves) << 16 | (infinite & 0xffff0000u);
}
// The narrow word of one 64-bit word given as its halves (`low`: lo and hi as bfloat16 codes,
// `high`: the bound's float bits); `bad` gains nonzero bits where the word has no narrow form.
inline uint32_t narrow_word_of(uint32_t low, uint32_t high, uint32_t& bad) {
  const uint32_t lo = narrow_code(low << 16, bad), hi = narrow_code(low & 0xffff0000u, bad);
  bad |= (hi - lo) >> 31;  // hi below lo
  return lo | hi << 8 | narrow_bound(high, bad);
}
// The narrow words of n 64-bit ones; false if some word has none (a range not of integers of
// 0..255 in order, or a bound not a multiple of a half up to 32767 nor +inf), and then what was
// written to `narrow` means nothing.
bool narrow_bounds(const uint64_t* words, size_t n, uint32_t* narrow);
// range_bound (of the compact records) of a narrow word's 64-bit word, without it: the
// same floats (a byte's float is its bfloat16's, a count of halves' half is exact).
inline DiamondBounds narrow_range_bound(uint32_t narrow) {
  const uint32_t halves = narrow >> 16;
  return {static_cast<float>(narrow & 0xffu), static_cast<float>(narrow >> 8 & 0xffu),
          halves == 0xffffu ? std::numeric_limits<float>::infinity() : 0.5f * static_cast<float>(halves), 0.0f};
}
// The 64-bit word of a narrow one (not of kUnsetNarrowBounds, which marks no record).
inline uint64_t widen_bounds(uint32_t narrow) {
  const auto code = [](uint32_t byte) { return uint64_t{std::bit_cast<uint32_t>(static_cast<float>(byte)) >> 16}; };
  const uint32_t halves = narrow >> 16;
  const float bound = halves == 0xffffu ? std::numeric_limits<float>::infinity() : 0.5f * static_cast<float>(halves);
  return code(narrow & 0xffu) | code(narrow >> 8 & 0xffu) << 16 | uint64_t{std::bit_cast<uint32_t>(bound)} << 32;
}

}  // namespace isotope
