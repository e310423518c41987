#pragma once
// A 64-bit integer hash for choices that must look random yet be the same on every run, thread
// and process: splitmix64's finalizer, a bijection whose every output bit depends on every input
// bit.
#include <cstdint>

namespace isotope {

inline uint64_t mix64(uint64_t x) {
  x ^= x >> 30;
  x *= 0xbf58476d1ce4e5b9ull;
  x ^= x >> 27;
  x *= 0x94d049bb133111ebull;
  return x ^ (x >> 31);
}

}  // namespace isotope
