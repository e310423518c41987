#include "io/ply_writer.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cstdint>
#include <cstring>
#include <limits>
#include <vector>

#include "io/atomic_file.h"
#include "io/io_error.h"

namespace isotope {
namespace {

constexpr size_t kBlockItems = size_t{1} << 16;  // items per buffered write

template <typename T>
unsigned char* put_le(unsigned char* p, T value) {
  std::array<unsigned char, sizeof(T)> b = std::bit_cast<std::array<unsigned char, sizeof(T)>>(value);
  if constexpr (std::endian::native == std::endian::big) std::reverse(b.begin(), b.end());
  std::memcpy(p, b.data(), sizeof(T));
  return p + sizeof(T);
}

// PLY indices are signed 32-bit, and a dangling index would make a file other tools reject.
void check_mesh(const Mesh& mesh, const std::string& path) {
  const size_t n = mesh.positions.size();
  if (n > static_cast<size_t>(std::numeric_limits<int32_t>::max()))
    throw IoError(path + ": " + std::to_string(n) + " vertices exceed the PLY int index range");
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    for (uint32_t v : mesh.triangles[t]) {
      if (v >= n) {
        throw IoError(path + ": triangle " + std::to_string(t) + " references vertex " + std::to_string(v) +
                      " but the mesh has " + std::to_string(n) + " vertices");
      }
    }
  }
}

std::string header(const Mesh& mesh) {
  return "ply\nformat binary_little_endian 1.0\ncomment written by isotope\n"
         "element vertex " + std::to_string(mesh.positions.size()) +
         "\nproperty float x\nproperty float y\nproperty float z\n"
         "element face " + std::to_string(mesh.triangles.size()) +
         "\nproperty list uchar int vertex_indices\nend_header\n";
}

// Encodes `items` into fixed-size records a block at a time, so a large mesh costs a few
// hundred writes and one block of memory.
template <typename Items, typename Encode>
void write_records(AtomicFile& out, const Items& items, size_t record_bytes, Encode encode) {
  std::vector<unsigned char> buffer(std::min(kBlockItems, items.size()) * record_bytes);
  for (size_t i = 0; i < items.size(); i += kBlockItems) {
    const size_t n = std::min(kBlockItems, items.size() - i);
    unsigned char* p = buffer.data();
    for (size_t k = 0; k < n; ++k) p = encode(p, items[i + k]);
    out.write(buffer.data(), n * record_bytes);
  }
}

void write_vertices(AtomicFile& out, const Mesh& mesh) {
  write_records(out, mesh.positions, 12, [](unsigned char* p, const std::array<float, 3>& v) {
    for (float c : v) p = put_le(p, c);
    return p;
  });
}

void write_faces(AtomicFile& out, const Mesh& mesh) {
  write_records(out, mesh.triangles, 13, [](unsigned char* p, const std::array<uint32_t, 3>& t) {
    p = put_le(p, uint8_t{3});
    for (uint32_t v : t) p = put_le(p, static_cast<int32_t>(v));
    return p;
  });
}

}  // namespace

void write_ply(const Mesh& mesh, const std::string& path) {
  check_mesh(mesh, path);
  AtomicFile out(path);
  const std::string head = header(mesh);
  out.write(head.data(), head.size());
  write_vertices(out, mesh);
  write_faces(out, mesh);
  out.commit();
}

}  // namespace isotope
