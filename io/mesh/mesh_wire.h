#pragma once
// The mesh as `isotope serve` sends it (docs/SERVE.md): a 20-byte header, the report as JSON, then
// positions, normals and indices as flat little-endian arrays that a browser hands to WebGL
// without a parse: every array starts on a 4-byte boundary.
#include <array>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "isotope/mesh.h"

namespace isotope {

inline constexpr std::array<char, 4> kMeshWireMagic = {'I', 'S', 'O', 'M'};
inline constexpr uint32_t kMeshWireVersion = 1;

// The wire bytes of a mesh as four pieces, its arrays left where they lie: the header with the
// report and its padding (owned), then views of the positions, the normals and the indices, valid
// while mesh and normals live unchanged. A server hands them to its socket one after the other,
// where a copy of 1 M triangles was 23 MB of fresh memory per response. Throws InvalidInput
// when the mesh or the report does not fit the format's 32-bit counts.
struct MeshWirePieces {
  std::string head;
  std::array<std::string_view, 3> arrays;
  // The four pieces in the order they are sent.
  std::array<std::string_view, 4> parts() const { return {head, arrays[0], arrays[1], arrays[2]}; }
  size_t size() const {
    size_t n = 0;
    for (const std::string_view p : parts()) n += p.size();
    return n;
  }
};
MeshWirePieces mesh_wire_pieces(const Mesh& mesh, const std::vector<std::array<float, 3>>& normals,
                                std::string_view report_json);

// The pieces joined in one string. Throws as mesh_wire_pieces.
std::string encode_mesh_wire(const Mesh& mesh, const std::vector<std::array<float, 3>>& normals,
                             std::string_view report_json);

struct MeshWire {
  std::string report_json;
  Mesh mesh;
  std::vector<std::array<float, 3>> normals;
};
// Throws std::runtime_error on a wrong magic, version or size (for tests and clients in C++).
MeshWire decode_mesh_wire(std::string_view bytes);

}  // namespace isotope
