#pragma once
// Building test files byte by byte: reading and writing them whole, typed values in either byte
// order, and gzip members as teem writes them (the NRRD, box-reader and store tests).
#include <gtest/gtest.h>
#include <zlib.h>

#include <algorithm>
#include <array>
#include <bit>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

namespace isotope::testing {

using Bytes = std::vector<unsigned char>;

inline Bytes read_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// SIZE bytes at DATA, replacing the file.
inline void write_bytes(const std::string& path, const void* data, size_t size) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(static_cast<const char*>(data), static_cast<std::streamsize>(size));
  ASSERT_TRUE(out.good()) << path;
}

// VALUES as this machine holds them, replacing the file.
template <typename T>
void write_values(const std::string& path, const std::vector<T>& values) {
  write_bytes(path, values.data(), values.size() * sizeof(T));
}

// TEXT, then DATA, replacing the file.
inline void write_file(const std::string& path, const std::string& text, const Bytes& data = {}) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(text.data(), static_cast<std::streamsize>(text.size()));
  out.write(reinterpret_cast<const char*>(data.data()), static_cast<std::streamsize>(data.size()));
  ASSERT_TRUE(out.good()) << path;
}

template <typename T>
Bytes bytes_of(const std::vector<T>& values, std::endian order) {
  Bytes out;
  for (T v : values) {
    auto b = std::bit_cast<std::array<unsigned char, sizeof(T)>>(v);
    if (order != std::endian::native) std::reverse(b.begin(), b.end());
    out.insert(out.end(), b.begin(), b.end());
  }
  return out;
}

// A complete gzip member (header, deflate data, CRC-32 and length), as teem writes it.
inline Bytes gzip(const Bytes& data) {
  z_stream zs{};
  EXPECT_EQ(deflateInit2(&zs, Z_BEST_SPEED, Z_DEFLATED, 16 + MAX_WBITS, 8, Z_DEFAULT_STRATEGY), Z_OK);
  Bytes out(deflateBound(&zs, static_cast<uLong>(data.size())));
  zs.next_in = const_cast<Bytef*>(data.data());
  zs.avail_in = static_cast<uInt>(data.size());
  zs.next_out = out.data();
  zs.avail_out = static_cast<uInt>(out.size());
  EXPECT_EQ(deflate(&zs, Z_FINISH), Z_STREAM_END);
  out.resize(zs.total_out);
  deflateEnd(&zs);
  return out;
}

}  // namespace isotope::testing
