#pragma once
// Plain values and arrays into bytes and back, for what processes hand each other (the parts of a
// mesh, a rank's counts: isotope::Distribution). Same machine type on both ends (one
// cluster, one build), so values go as they are in memory; a reader that runs past the end throws.
#include <cstdint>
#include <cstring>
#include <stdexcept>
#include <type_traits>
#include <vector>

#include "isotope/error.h"

namespace isotope {

class ByteWriter {
 public:
  template <class T>
  void put(const T& v) {
    static_assert(std::is_trivially_copyable_v<T>);
    append(&v, sizeof(T));
  }
  // The count, then the elements.
  template <class Array>
  void put_array(const Array& a) {
    using T = typename Array::value_type;
    static_assert(std::is_trivially_copyable_v<T>);
    put(static_cast<uint64_t>(a.size()));
    append(a.data(), a.size() * sizeof(T));
  }
  std::vector<uint8_t>& bytes() { return bytes_; }

 private:
  // resize and memcpy rather than insert: g++ 12 sees a false overflow in insert's inlined memmove.
  void append(const void* p, size_t n) {
    if (n == 0) return;
    const size_t at = bytes_.size();
    bytes_.resize(at + n);
    std::memcpy(bytes_.data() + at, p, n);
  }
  std::vector<uint8_t> bytes_;
};

class ByteReader {
 public:
  explicit ByteReader(const std::vector<uint8_t>& bytes) : at_(bytes.data()), end_(bytes.data() + bytes.size()) {}
  template <class T>
  T get() {
    T v;
    take(&v, sizeof(T));
    return v;
  }
  template <class Array>
  void get_array(Array& a) {
    using T = typename Array::value_type;
    const auto n = get<uint64_t>();
    if (n > static_cast<uint64_t>(end_ - at_) / sizeof(T)) throw Error("a rank's data is truncated");
    a.resize(n);
    take(a.data(), n * sizeof(T));
  }
  bool done() const { return at_ == end_; }

 private:
  void take(void* out, size_t n) {
    if (n > static_cast<size_t>(end_ - at_)) throw Error("a rank's data is truncated");
    if (n > 0) std::memcpy(out, at_, n);
    at_ += n;
  }
  const uint8_t* at_;
  const uint8_t* end_;
};

}  // namespace isotope
