#include "io/mesh/mesh_wire.h"

#include <bit>
#include <cstring>
#include <limits>
#include <stdexcept>

#include "isotope/error.h"

namespace isotope {
namespace {

static_assert(std::endian::native == std::endian::little, "the wire format is little-endian");

void put_u32(std::string& out, uint32_t v) { out.append(reinterpret_cast<const char*>(&v), 4); }

template <class T>
std::string_view bytes_of(const T* data, size_t count) {
  return {reinterpret_cast<const char*>(data), count * sizeof(T)};
}

uint32_t checked_u32(size_t n, const char* what) {
  if (n > std::numeric_limits<uint32_t>::max())
    throw InvalidInput(std::string("too many ") + what + " for the mesh wire format");
  return static_cast<uint32_t>(n);
}

size_t padded(size_t n) { return (n + 3) & ~size_t{3}; }

}  // namespace

MeshWirePieces mesh_wire_pieces(const Mesh& mesh, const std::vector<std::array<float, 3>>& normals,
                                std::string_view report_json) {
  if (normals.size() != mesh.positions.size()) throw InvalidInput("one normal per vertex");
  const uint32_t vertices = checked_u32(mesh.positions.size(), "vertices");
  const uint32_t triangles = checked_u32(mesh.triangles.size(), "triangles");
  const uint32_t json_bytes = checked_u32(report_json.size(), "report bytes");
  MeshWirePieces out;
  out.head.reserve(20 + padded(json_bytes));
  out.head.append(kMeshWireMagic.data(), 4);
  put_u32(out.head, kMeshWireVersion);
  put_u32(out.head, json_bytes);
  put_u32(out.head, vertices);
  put_u32(out.head, triangles);
  out.head.append(report_json);
  out.head.append(padded(json_bytes) - json_bytes, ' ');
  out.arrays = {bytes_of(mesh.positions.data(), mesh.positions.size()), bytes_of(normals.data(), normals.size()),
                bytes_of(mesh.triangles.data(), mesh.triangles.size())};
  return out;
}

std::string encode_mesh_wire(const Mesh& mesh, const std::vector<std::array<float, 3>>& normals,
                             std::string_view report_json) {
  const MeshWirePieces pieces = mesh_wire_pieces(mesh, normals, report_json);
  std::string out;
  out.reserve(pieces.size());
  for (const std::string_view p : pieces.parts()) out.append(p);
  return out;
}

MeshWire decode_mesh_wire(std::string_view bytes) {
  auto u32_at = [&](size_t at) {
    uint32_t v;
    std::memcpy(&v, bytes.data() + at, 4);
    return v;
  };
  if (bytes.size() < 20 || std::memcmp(bytes.data(), kMeshWireMagic.data(), 4) != 0)
    throw IoError("not an isotope mesh (magic ISOM)");
  if (u32_at(4) != kMeshWireVersion) throw IoError("unsupported mesh wire version");
  const size_t json = u32_at(8), vertices = u32_at(12), triangles = u32_at(16);
  const size_t json_end = 20 + padded(json);
  if (bytes.size() != json_end + 24 * vertices + 12 * triangles)
    throw IoError("mesh wire size does not match its counts");
  MeshWire w;
  w.report_json.assign(bytes.substr(20, json));
  w.mesh.positions.resize(vertices);
  w.normals.resize(vertices);
  w.mesh.triangles.resize(triangles);
  std::memcpy(w.mesh.positions.data(), bytes.data() + json_end, 12 * vertices);
  std::memcpy(w.normals.data(), bytes.data() + json_end + 12 * vertices, 12 * vertices);
  std::memcpy(w.mesh.triangles.data(), bytes.data() + json_end + 24 * vertices, 12 * triangles);
  for (const auto& t : w.mesh.triangles)
    for (const uint32_t i : t)
      if (i >= vertices) throw IoError("mesh wire index out of range");
  return w;
}

}  // namespace isotope
