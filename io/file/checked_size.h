#pragma once
// Overflow-safe arithmetic for sizes, offsets and counts read from files. A check written
// as `offset + size <= end` wraps when a crafted file puts both near 2^64, and then passes; every
// reader that takes a number from a file and compares it, multiplies it or allocates by it goes
// through these two instead (the store's reader and format, the raw reader, and
// through checked_node_count the NRRD, HDF5 and volume readers).
#include <cstdint>
#include <optional>
#include <type_traits>

namespace isotope {

// A * B, or nothing when it does not fit in T.
template <class T>
requires std::is_integral_v<T>
constexpr std::optional<T> checked_mul(T a, T b) {
  T product;
  if (__builtin_mul_overflow(a, b, &product)) return std::nullopt;
  return product;
}

// Whether the SIZE bytes at OFFSET lie inside [0, END): never forms OFFSET + SIZE, so it cannot wrap.
constexpr bool range_within(uint64_t offset, uint64_t size, uint64_t end) {
  return offset <= end && size <= end - offset;
}

}  // namespace isotope
