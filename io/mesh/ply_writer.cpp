#include "io/mesh/ply_writer.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cstdint>
#include <cstring>
#include <limits>
#include <vector>

#include "engine/core/parallel.h"
#include "io/file/atomic_file.h"
#include "isotope/error.h"

namespace isotope {
namespace {

constexpr size_t kBlockItems = size_t{1} << 16;  // items per buffered write
constexpr size_t kWindowBlocks = 8;              // blocks encoded at once, in parallel

template <typename T>
unsigned char* put_le(unsigned char* p, T value) {
  std::array<unsigned char, sizeof(T)> b = std::bit_cast<std::array<unsigned char, sizeof(T)>>(value);
  if constexpr (std::endian::native == std::endian::big) std::reverse(b.begin(), b.end());
  std::memcpy(p, b.data(), sizeof(T));
  return p + sizeof(T);
}

// PLY indices are signed 32-bit. (A dangling index, which would make a file other tools reject,
// is caught while the faces are encoded: write_faces.)
void check_mesh(const Mesh& mesh, const std::string& path) {
  const size_t n = mesh.positions.size();
  if (n > static_cast<size_t>(std::numeric_limits<int32_t>::max()))
    throw IoError(path + ": " + std::to_string(n) + " vertices exceed the PLY int index range");
}

std::string header(const Mesh& mesh) {
  return "ply\nformat binary_little_endian 1.0\ncomment written by isotope\n"
         "element vertex " +
         std::to_string(mesh.positions.size()) +
         "\nproperty float x\nproperty float y\nproperty float z\n"
         "element face " +
         std::to_string(mesh.triangles.size()) + "\nproperty list uchar int vertex_indices\nend_header\n";
}

// Encodes `items` into fixed-size records a window of blocks at a time, the blocks of a window on
// all threads, so a large mesh costs a few hundred writes and a few blocks of memory, and its
// encoding scales with the threads (a whole extraction written on one thread did not: issue 17).
template <typename Items, typename Encode>
void write_records(AtomicFile& out, const Items& items, size_t record_bytes, Encode encode) {
  const size_t blocks = (items.size() + kBlockItems - 1) / kBlockItems;
  std::vector<std::vector<unsigned char>> buffers(std::min(kWindowBlocks, blocks));
  for (size_t first = 0; first < blocks; first += buffers.size()) {
    const size_t count = std::min(buffers.size(), blocks - first);
    parallel_for(int64_t{0}, static_cast<int64_t>(count), [&](int64_t b) {
      const size_t begin = (first + static_cast<size_t>(b)) * kBlockItems;
      const size_t n = std::min(kBlockItems, items.size() - begin);
      std::vector<unsigned char>& buffer = buffers[static_cast<size_t>(b)];
      buffer.resize(n * record_bytes);
      unsigned char* p = buffer.data();
      for (size_t k = 0; k < n; ++k) p = encode(p, items[begin + k]);
    });
    for (size_t b = 0; b < count; ++b) out.write(buffers[b].data(), buffers[b].size());
  }
}

void write_vertices(AtomicFile& out, const Mesh& mesh) {
  write_records(out, mesh.positions, 12, [](unsigned char* p, const std::array<float, 3>& v) {
    for (float c : v) p = put_le(p, c);
    return p;
  });
}

void write_faces(AtomicFile& out, const Mesh& mesh, const std::string& path) {
  const size_t n = mesh.positions.size();
  write_records(out, mesh.triangles, 13, [&](unsigned char* p, const std::array<uint32_t, 3>& t) {
    p = put_le(p, uint8_t{3});
    for (uint32_t v : t) {
      if (v >= n)
        throw IoError(path + ": triangle " + std::to_string(&t - mesh.triangles.data()) + " references vertex " +
                      std::to_string(v) + " but the mesh has " + std::to_string(n) + " vertices");
      p = put_le(p, static_cast<int32_t>(v));
    }
    return p;
  });
}

}  // namespace

void write_ply(const Mesh& mesh, AtomicFile& out) {
  check_mesh(mesh, out.path());
  const std::string head = header(mesh);
  out.write(head.data(), head.size());
  write_vertices(out, mesh);
  write_faces(out, mesh, out.path());
  out.finish();
}

void write_ply(const Mesh& mesh, const std::string& path) {
  check_mesh(mesh, path);
  AtomicFile out(path);
  write_ply(mesh, out);
  out.commit();
}

}  // namespace isotope
