#include "io/mesh/mesh_writer.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <limits>
#include <memory>
#include <span>
#include <utility>
#include <vector>

#include "engine/core/huge_blocks.h"
#include "engine/core/parallel.h"
#include "engine/mesh/vertex_normals.h"
#include "io/file/extension.h"
#include "isotope/error.h"
#include "isotope/version.h"

namespace isotope {
namespace {

constexpr size_t kBlockItems = size_t{1} << 16;  // items per buffered write
constexpr size_t kWindowBlocks = 8;              // blocks encoded at once, in parallel

// Records of RECORD_BYTES per block of a region (AtomicFile::append_region): a block that large
// reaches the disk in one direct write (AtomicFile::kRegionPieceBytes).
constexpr size_t region_block_items(size_t record_bytes) { return AtomicFile::kRegionPieceBytes / record_bytes; }

// Megabytes per window of blocks: on huge pages where a buffer takes 2 MB or more (HugePageAllocator).
using Bytes = std::vector<unsigned char, detail::HugePageAllocator<unsigned char>>;

// Room for BYTES more in BUFFER, its pages faulted in by one call before an encoder writes them a
// few bytes at a time (docs/METHOD.md, "Fresh memory"): OBJ's text of embryo's eps 0 mesh took
// 8,000 page faults in its buffers.
void reserve_prefaulted(Bytes& buffer, size_t bytes) {
  buffer.reserve(buffer.size() + bytes);
  detail::prefault(buffer.data() + buffer.size(), buffer.capacity() - buffer.size());
}

template <typename T>
unsigned char* put_le(unsigned char* p, T value) {
  std::array<unsigned char, sizeof(T)> b = std::bit_cast<std::array<unsigned char, sizeof(T)>>(value);
  if constexpr (std::endian::native == std::endian::big) std::reverse(b.begin(), b.end());
  std::memcpy(p, b.data(), sizeof(T));
  return p + sizeof(T);
}

void write_text(AtomicFile& out, const std::string& text) { out.write(text.data(), text.size()); }

void write_u64(AtomicFile& out, uint64_t value) {
  std::array<unsigned char, 8> bytes;
  put_le(bytes.data(), value);
  out.write(bytes.data(), bytes.size());
}

// The greatest vertex index of TRIANGLES (0 for none): tested once, where a test per index and a
// store of the verdict kept the loop from running without branches.
uint32_t greatest_index(std::span<const std::array<uint32_t, 3>> triangles) {
  uint32_t greatest = 0;
  for (const auto& t : triangles) greatest = std::max({greatest, t[0], t[1], t[2]});
  return greatest;
}

// A dangling index would make a file other tools reject (or, for the formats that store corners,
// read outside the positions): refused before anything is encoded (PLY, which only copies the
// indices, checks each block as it encodes it: write_ply_faces).
void check_indices(const Mesh& mesh, const std::string& path) {
  const size_t n = mesh.positions.size();
  const int64_t blocks = static_cast<int64_t>((mesh.triangles.size() + kBlockItems - 1) / kBlockItems);
  std::atomic<bool> bad{false};  // on all threads; the serial scan below only names the first
  parallel_for(int64_t{0}, blocks, [&](int64_t b) {
    const size_t begin = static_cast<size_t>(b) * kBlockItems;
    const size_t end = std::min(mesh.triangles.size(), begin + kBlockItems);
    if (greatest_index(std::span(mesh.triangles.data() + begin, end - begin)) >= n) bad = true;
  });
  if (!bad) return;
  for (size_t t = 0; t < mesh.triangles.size(); ++t)
    for (uint32_t v : mesh.triangles[t])
      if (v >= n)
        throw IoError(path + ": triangle " + std::to_string(t) + " references vertex " + std::to_string(v) +
                      " but the mesh has " + std::to_string(n) + " vertices");
}

void check_count(size_t count, size_t limit, const std::string& path, const char* what, const char* format) {
  if (count > limit)
    throw IoError(path + ": " + std::to_string(count) + " " + what + " exceed the " + format + " range");
}

// Encodes `count` items a window of blocks at a time, the blocks of a window on all threads, so a
// large mesh costs a few hundred writes and a few blocks of memory, and its encoding scales with
// the threads (a whole extraction written on one thread did not). ENCODE(begin, end,
// buffer) appends items [begin, end) to an empty buffer.
template <typename Encode>
void write_blocks(AtomicFile& out, size_t count, Encode encode) {
  const size_t blocks = (count + kBlockItems - 1) / kBlockItems;
  std::vector<Bytes> buffers(std::min(kWindowBlocks, blocks));
  for (size_t first = 0; first < blocks; first += buffers.size()) {
    const size_t window = std::min(buffers.size(), blocks - first);
    parallel_for(int64_t{0}, static_cast<int64_t>(window), [&](int64_t b) {
      const size_t begin = (first + static_cast<size_t>(b)) * kBlockItems;
      Bytes& buffer = buffers[static_cast<size_t>(b)];
      buffer.clear();
      encode(begin, std::min(count, begin + kBlockItems), buffer);
    });
    for (size_t b = 0; b < window; ++b) out.write(buffers[b].data(), buffers[b].size());
  }
}

// Records ITEMS[0..) of RECORD_BYTES each (at most region_block_items), the first being record FIRST of
// a region append_region() made at AT: PUT(p, item) writes one at p and returns the end. Encoded
// straight into the place the calling thread writes them from (AtomicFile::fill_region).
template <typename Item, typename Put>
void write_record_block(const AtomicFile& out, uint64_t at, size_t first, std::span<const Item> items,
                        size_t record_bytes, Put put) {
  out.fill_region(at + first * record_bytes, items.size() * record_bytes, [&](unsigned char* p) {
    for (const Item& item : items) p = put(p, item);
  });
}

// Items of RECORD_BYTES each: PUT(p, item) writes one at p and returns the end. Every block's
// place in the file is known, so each is encoded and written by one thread, all threads at once
// (write_record_block).
template <typename Items, typename Put>
void write_records(AtomicFile& out, const Items& items, size_t record_bytes, Put put) {
  const size_t count = items.size();
  const uint64_t at = out.append_region(count * record_bytes);
  const size_t block = region_block_items(record_bytes);
  parallel_for(int64_t{0}, static_cast<int64_t>((count + block - 1) / block), [&](int64_t b) {
    const size_t begin = static_cast<size_t>(b) * block, end = std::min(count, begin + block);
    write_record_block(out, at, begin, std::span(items.data() + begin, end - begin), record_bytes, put);
  });
}

unsigned char* put_vec3(unsigned char* p, const std::array<float, 3>& v) {
  for (float c : v) p = put_le(p, c);
  return p;
}

// Items whose records are their own values back to back, little-endian (positions as float x, y,
// z; indices as 32-bit integers). On a little-endian machine those are the bytes in memory: each
// block is written straight from the mesh's array, on all threads at once, with nothing encoded
// (encoding them cost a pass over the array and a buffer as large as the block, for a copy).
template <typename Items>
void write_as_stored(AtomicFile& out, const Items& items) {
  using Item = typename Items::value_type;
  using Value = typename Item::value_type;
  static_assert(sizeof(Item) == std::tuple_size_v<Item> * sizeof(Value), "records without padding");
  if constexpr (std::endian::native == std::endian::little) {
    const size_t count = items.size();
    const uint64_t at = out.append_region(count * sizeof(Item));
    const size_t block = region_block_items(sizeof(Item));
    parallel_for(int64_t{0}, static_cast<int64_t>((count + block - 1) / block), [&](int64_t b) {
      const size_t begin = static_cast<size_t>(b) * block, end = std::min(count, begin + block);
      out.write_region(at + begin * sizeof(Item), items.data() + begin, (end - begin) * sizeof(Item));
    });
  } else {
    write_records(out, items, sizeof(Item), [](unsigned char* p, const Item& item) {
      for (Value v : item) p = put_le(p, v);
      return p;
    });
  }
}

// ---- PLY ----

unsigned char* put_ply_face(unsigned char* p, const std::array<uint32_t, 3>& t) {
  *p++ = 3;
  if constexpr (std::endian::native == std::endian::little) {
    std::memcpy(p, t.data(), 12);  // a uint32 index and its int32 have the same bytes
    return p + 12;
  }
  for (uint32_t v : t) p = put_le(p, static_cast<int32_t>(v));
  return p;
}

// The faces as write_records would write them, each block's indices checked against the vertex
// count just before it is encoded, from the cache, where check_indices reads the whole array from
// memory once more. A block that fails is not written, and check_indices names the first dangling
// index (the file is left unfinished: AtomicFile discards it).
void write_ply_faces(AtomicFile& out, const Mesh& mesh) {
  const size_t count = mesh.triangles.size(), n = mesh.positions.size();
  const uint64_t at = out.append_region(count * 13);
  std::atomic<bool> bad{false};
  const size_t block_items = region_block_items(13);
  parallel_for(int64_t{0}, static_cast<int64_t>((count + block_items - 1) / block_items), [&](int64_t b) {
    const size_t begin = static_cast<size_t>(b) * block_items, end = std::min(count, begin + block_items);
    const std::span<const std::array<uint32_t, 3>> block(mesh.triangles.data() + begin, end - begin);
    if (greatest_index(block) >= n) {
      bad = true;
      return;
    }
    write_record_block(out, at, begin, block, 13, put_ply_face);
  });
  if (bad) check_indices(mesh, out.path());
}

void encode_ply(const Mesh& mesh, AtomicFile& out) {
  check_count(mesh.positions.size(), std::numeric_limits<int32_t>::max(), out.path(), "vertices", "PLY int index");
  write_text(out, "ply\nformat binary_little_endian 1.0\ncomment written by isotope\nelement vertex " +
                      std::to_string(mesh.positions.size()) +
                      "\nproperty float x\nproperty float y\nproperty float z\nelement face " +
                      std::to_string(mesh.triangles.size()) + "\nproperty list uchar int vertex_indices\nend_header\n");
  write_as_stored(out, mesh.positions);
  write_ply_faces(out, mesh);
}

// ---- OBJ ----

// Shortest text that reads back as the same float (std::to_chars), so OBJ loses nothing.
template <typename T>
void append_number(Bytes& buffer, T value) {
  char text[32];
  const auto end = std::to_chars(text, text + sizeof text, value).ptr;
  buffer.insert(buffer.end(), text, end);
}

void encode_obj(const Mesh& mesh, AtomicFile& out) {
  write_text(out, "# written by isotope " ISOTOPE_VERSION_STRING ": " + std::to_string(mesh.positions.size()) +
                      " vertices, " + std::to_string(mesh.triangles.size()) + " triangles\n");
  write_blocks(out, mesh.positions.size(), [&](size_t begin, size_t end, Bytes& buffer) {
    reserve_prefaulted(buffer, (end - begin) * 36);
    for (size_t i = begin; i < end; ++i) {
      buffer.push_back('v');
      for (float c : mesh.positions[i]) {
        buffer.push_back(' ');
        append_number(buffer, c);
      }
      buffer.push_back('\n');
    }
  });
  write_blocks(out, mesh.triangles.size(), [&](size_t begin, size_t end, Bytes& buffer) {
    reserve_prefaulted(buffer, (end - begin) * 24);
    for (size_t t = begin; t < end; ++t) {
      buffer.push_back('f');
      for (uint32_t v : mesh.triangles[t]) {
        buffer.push_back(' ');
        append_number(buffer, uint64_t{v} + 1);  // OBJ counts vertices from 1
      }
      buffer.push_back('\n');
    }
  });
}

// ---- STL ----

std::array<float, 3> unit_normal(const std::array<float, 3>& a, const std::array<float, 3>& b,
                                 const std::array<float, 3>& c) {
  const double u[3] = {double(b[0]) - a[0], double(b[1]) - a[1], double(b[2]) - a[2]};
  const double v[3] = {double(c[0]) - a[0], double(c[1]) - a[1], double(c[2]) - a[2]};
  const double n[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]};
  const double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
  if (!(len > 0)) return {0, 0, 0};  // a degenerate triangle: STL readers recompute it
  return {static_cast<float>(n[0] / len), static_cast<float>(n[1] / len), static_cast<float>(n[2] / len)};
}

void encode_stl(const Mesh& mesh, AtomicFile& out) {
  check_count(mesh.triangles.size(), std::numeric_limits<uint32_t>::max(), out.path(), "triangles", "STL count");
  // 80 bytes of header that must not begin with "solid" (the text format's first word).
  std::array<unsigned char, 84> head{};
  std::fill(head.begin(), head.begin() + 80, ' ');
  const std::string title = "binary STL written by isotope " ISOTOPE_VERSION_STRING;
  std::memcpy(head.data(), title.data(), title.size());
  put_le(head.data() + 80, static_cast<uint32_t>(mesh.triangles.size()));
  out.write(head.data(), head.size());
  write_records(out, mesh.triangles, 50, [&](unsigned char* p, const std::array<uint32_t, 3>& t) {
    const auto& a = mesh.positions[t[0]];
    const auto& b = mesh.positions[t[1]];
    const auto& c = mesh.positions[t[2]];
    p = put_vec3(p, unit_normal(a, b, c));
    p = put_vec3(put_vec3(put_vec3(p, a), b), c);
    return put_le(p, uint16_t{0});  // attribute byte count
  });
}

// The vertex normals (isotope::vertex_normals) as records of 12 bytes, each run of them encoded
// and written by the thread that finished it (write_record_block), with no array of the normals
// held (for_each_vertex_normals_run). A vertex whose triangles are all degenerate has none and
// gets NONE: glTF requires unit length, so its writer gives +z, which no shading of a zero-area
// triangle can show; VTK's takes 0, as isotope::vertex_normals gives.
void write_normals(AtomicFile& out, const Mesh& mesh, const std::array<float, 3>& none) {
  static_assert(kNormalsPerRun <= region_block_items(12), "a run of normals is written as one block");
  const uint64_t at = out.append_region(mesh.positions.size() * 12);
  for_each_vertex_normals_run(mesh, none, [&](uint32_t first, std::span<const std::array<float, 3>> normals) {
    write_record_block(out, at, first, normals, 12, put_vec3);
  });
}

// The least and greatest coordinates of the positions, on all threads (the same on any number:
// a minimum is a minimum in any order). Not empty.
std::array<std::array<float, 3>, 2> bounds(const Mesh::Array<std::array<float, 3>>& positions) {
  const auto blocks = static_cast<int64_t>((positions.size() + kBlockItems - 1) / kBlockItems);
  std::vector<std::array<std::array<float, 3>, 2>> block_bounds(static_cast<size_t>(blocks));
  parallel_for(int64_t{0}, blocks, [&](int64_t b) {
    const size_t begin = static_cast<size_t>(b) * kBlockItems, end = std::min(positions.size(), begin + kBlockItems);
    std::array<float, 3> lo = positions[begin], hi = lo;
    for (size_t i = begin; i < end; ++i)
      for (int k = 0; k < 3; ++k) lo[k] = std::min(lo[k], positions[i][k]), hi[k] = std::max(hi[k], positions[i][k]);
    block_bounds[static_cast<size_t>(b)] = {lo, hi};
  });
  std::array<std::array<float, 3>, 2> all = block_bounds[0];
  for (const auto& [lo, hi] : block_bounds)
    for (int k = 0; k < 3; ++k) all[0][k] = std::min(all[0][k], lo[k]), all[1][k] = std::max(all[1][k], hi[k]);
  return all;
}

// ---- glTF binary ----

std::string json_number(double value) {
  char text[40];
  return std::string(text, std::to_chars(text, text + sizeof text, value).ptr);
}

std::string json_vec3(const std::array<float, 3>& v) {
  return "[" + json_number(v[0]) + "," + json_number(v[1]) + "," + json_number(v[2]) + "]";
}

// The glTF 2.0 binary container (GLB): a 12-byte header, a JSON chunk describing one mesh of one
// triangle primitive, and a BIN chunk holding positions, normals and indices back to back. Written
// here, not with tinygltf (libtinygltf-dev): its writer takes a copy of every buffer into its model
// and writes to a stream or a path of its own, where a mesh of hundreds of megabytes needs to be
// streamed, block by block, through AtomicFile; the container itself is three headers.
void encode_glb(const Mesh& mesh, AtomicFile& out) {
  const uint64_t n = mesh.positions.size(), m = mesh.triangles.size();
  std::string json =
      "{\"asset\":{\"version\":\"2.0\",\"generator\":\"isotope " ISOTOPE_VERSION_STRING "\"},\"scene\":0,";
  uint64_t bin = 0;
  if (m == 0) {
    json += "\"scenes\":[{}]}";  // an accessor must count at least one element: no mesh at all
  } else {
    const auto [lo, hi] = bounds(mesh.positions);
    bin = 24 * n + 12 * m;
    json +=
        "\"scenes\":[{\"nodes\":[0]}],\"nodes\":[{\"mesh\":0}],"
        "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0,\"NORMAL\":1},\"indices\":2,\"mode\":4}]}],"
        "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":" +
        std::to_string(n) + ",\"type\":\"VEC3\",\"min\":" + json_vec3(lo) + ",\"max\":" + json_vec3(hi) +
        "},{\"bufferView\":1,\"componentType\":5126,\"count\":" + std::to_string(n) +
        ",\"type\":\"VEC3\"},{\"bufferView\":2,\"componentType\":5125,\"count\":" + std::to_string(3 * m) +
        ",\"type\":\"SCALAR\"}],\"bufferViews\":[{\"buffer\":0,\"byteOffset\":0,\"byteLength\":" +
        std::to_string(12 * n) + ",\"target\":34962},{\"buffer\":0,\"byteOffset\":" + std::to_string(12 * n) +
        ",\"byteLength\":" + std::to_string(12 * n) +
        ",\"target\":34962},{\"buffer\":0,\"byteOffset\":" + std::to_string(24 * n) +
        ",\"byteLength\":" + std::to_string(12 * m) +
        ",\"target\":34963}],\"buffers\":[{\"byteLength\":" + std::to_string(bin) + "}]}";
  }
  json.resize((json.size() + 3) / 4 * 4, ' ');  // chunks are 4-byte aligned; JSON pads with spaces
  const uint64_t total = 12 + 8 + json.size() + (bin > 0 ? 8 + bin : 0);  // bin is a multiple of 4
  check_count(total, std::numeric_limits<uint32_t>::max(), out.path(), "bytes", "glTF binary 4 GiB");
  std::array<unsigned char, 20> head;
  unsigned char* p = put_le(head.data(), uint32_t{0x46546C67});  // "glTF"
  p = put_le(p, uint32_t{2});
  p = put_le(p, static_cast<uint32_t>(total));
  p = put_le(p, static_cast<uint32_t>(json.size()));
  put_le(p, uint32_t{0x4E4F534A});  // "JSON"
  out.write(head.data(), head.size());
  write_text(out, json);
  if (bin == 0) return;
  p = put_le(head.data(), static_cast<uint32_t>(bin));
  put_le(p, uint32_t{0x004E4942});  // "BIN\0"
  out.write(head.data(), 8);
  write_as_stored(out, mesh.positions);
  write_normals(out, mesh, {0, 0, 1});
  write_as_stored(out, mesh.triangles);
}

// ---- VTK XML PolyData ----

// One piece with point normals, points and triangles as polys, in the raw appended encoding (each
// array a UInt64 byte count and its little-endian values), which ParaView and VTK read without a
// base64 pass. Indices are Int32 when they fit, else Int64.
template <typename Index>
void encode_vtp_polys(const Mesh& mesh, AtomicFile& out) {
  const uint64_t m = mesh.triangles.size();
  write_u64(out, 3 * m * sizeof(Index));
  if constexpr (sizeof(Index) == sizeof(uint32_t)) {
    write_as_stored(out, mesh.triangles);  // a uint32 index and its Int32 have the same bytes
  } else {
    write_records(out, mesh.triangles, 3 * sizeof(Index), [](unsigned char* p, const std::array<uint32_t, 3>& t) {
      for (uint32_t v : t) p = put_le(p, static_cast<Index>(v));
      return p;
    });
  }
  write_u64(out, m * sizeof(Index));
  write_blocks(out, m, [](size_t begin, size_t end, Bytes& buffer) {
    buffer.resize((end - begin) * sizeof(Index));
    unsigned char* p = buffer.data();
    for (size_t t = begin; t < end; ++t) p = put_le(p, static_cast<Index>(3 * (t + 1)));
  });
}

void encode_vtp(const Mesh& mesh, AtomicFile& out) {
  const uint64_t n = mesh.positions.size(), m = mesh.triangles.size();
  const bool wide = 3 * m > static_cast<uint64_t>(std::numeric_limits<int32_t>::max());
  const uint64_t index_bytes = wide ? 8 : 4;
  const char* index_type = wide ? "Int64" : "Int32";
  const uint64_t normals_at = 0, points_at = normals_at + 8 + 12 * n, connectivity_at = points_at + 8 + 12 * n,
                 offsets_at = connectivity_at + 8 + 3 * m * index_bytes;
  const auto array = [](const char* type, const char* name, int components, uint64_t offset) {
    return std::string("        <DataArray type=\"") + type + "\" Name=\"" + name + "\" NumberOfComponents=\"" +
           std::to_string(components) + "\" format=\"appended\" offset=\"" + std::to_string(offset) + "\"/>\n";
  };
  write_text(
      out, "<?xml version=\"1.0\"?>\n<!-- written by isotope " ISOTOPE_VERSION_STRING
           " -->\n<VTKFile type=\"PolyData\" version=\"1.0\" byte_order=\"LittleEndian\" "
           "header_type=\"UInt64\">\n  <PolyData>\n    <Piece NumberOfPoints=\"" +
               std::to_string(n) + "\" NumberOfVerts=\"0\" NumberOfLines=\"0\" NumberOfStrips=\"0\" NumberOfPolys=\"" +
               std::to_string(m) + "\">\n      <PointData Normals=\"Normals\">\n" +
               array("Float32", "Normals", 3, normals_at) + "      </PointData>\n      <Points>\n" +
               array("Float32", "Points", 3, points_at) + "      </Points>\n      <Polys>\n" +
               array(index_type, "connectivity", 1, connectivity_at) + array(index_type, "offsets", 1, offsets_at) +
               "      </Polys>\n    </Piece>\n  </PolyData>\n  <AppendedData encoding=\"raw\">\n   _");
  write_u64(out, 12 * n);
  write_normals(out, mesh, {0, 0, 0});
  write_u64(out, 12 * n);
  write_as_stored(out, mesh.positions);
  if (wide)
    encode_vtp_polys<int64_t>(mesh, out);
  else
    encode_vtp_polys<int32_t>(mesh, out);
  write_text(out, "\n  </AppendedData>\n</VTKFile>\n");
}

}  // namespace

std::optional<MeshFormat> mesh_format_of(const std::string& path) {
  const std::string ext = lowercase_extension(path);
  if (ext == ".ply") return MeshFormat::ply;
  if (ext == ".obj") return MeshFormat::obj;
  if (ext == ".stl") return MeshFormat::stl;
  if (ext == ".glb") return MeshFormat::glb;
  if (ext == ".vtp") return MeshFormat::vtp;
  return std::nullopt;
}

std::string unknown_mesh_format_message(const std::string& path) {
  const std::string ext = lowercase_extension(path);
  return path + ": " +
         (ext.empty() ? std::string("no extension to choose a mesh format by") : "unknown mesh format '" + ext + "'") +
         " (use .ply, .obj, .stl, .glb or .vtp)";
}

void write_mesh(const Mesh& mesh, AtomicFile& out, MeshFormat format) {
  if (format != MeshFormat::ply) check_indices(mesh, out.path());
  switch (format) {
    case MeshFormat::ply: encode_ply(mesh, out); break;
    case MeshFormat::obj: encode_obj(mesh, out); break;
    case MeshFormat::stl: encode_stl(mesh, out); break;
    case MeshFormat::glb: encode_glb(mesh, out); break;
    case MeshFormat::vtp: encode_vtp(mesh, out); break;
  }
  out.finish();
}

void write_ply(const Mesh& mesh, AtomicFile& out) { write_mesh(mesh, out, MeshFormat::ply); }

void write_ply(const Mesh& mesh, const std::string& path) {
  check_count(mesh.positions.size(), std::numeric_limits<int32_t>::max(), path, "vertices", "PLY int index");
  AtomicFile out(path);
  write_ply(mesh, out);
  out.commit();
}

void write_mesh(const Mesh& mesh, const std::string& path) {
  const std::optional<MeshFormat> format = mesh_format_of(path);
  if (!format) throw IoError(unknown_mesh_format_message(path));
  AtomicFile out(path);
  write_mesh(mesh, out, *format);
  out.commit();
}

void write_pvtp(const std::vector<std::string>& pieces, const std::string& path) {
  // The arrays each piece holds (encode_vtp above), declared once for all of them.
  std::string text =
      "<?xml version=\"1.0\"?>\n<!-- written by isotope " ISOTOPE_VERSION_STRING
      " -->\n<VTKFile type=\"PPolyData\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\">\n"
      "  <PPolyData GhostLevel=\"0\">\n    <PPointData Normals=\"Normals\">\n"
      "      <PDataArray type=\"Float32\" Name=\"Normals\" NumberOfComponents=\"3\"/>\n    </PPointData>\n"
      "    <PPoints>\n      <PDataArray type=\"Float32\" Name=\"Points\" NumberOfComponents=\"3\"/>\n"
      "    </PPoints>\n";
  for (const std::string& piece : pieces) text += "    <Piece Source=\"" + piece + "\"/>\n";
  text += "  </PPolyData>\n</VTKFile>\n";
  AtomicFile out(path);
  out.write(text.data(), text.size());
  out.commit();
}

}  // namespace isotope
