// Mesh formats as written: PLY's layout, every format read back to the same mesh, and what every
// format refuses.
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cstdint>
#include <cstdlib>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "engine/extract/extract_drivers.h"
#include "engine/mesh/vertex_normals.h"
#include "engine/synthetic/fields.h"
#include "io/mesh/mesh_writer.h"
#include "tests/support/byte_files.h"
#include "tests/support/io_error_of.h"
#include "tests/support/temp_dir_test.h"

namespace isotope {
namespace {

using MeshFormats = testing::TempDirTest;
using testing::io_error_of;
using testing::read_bytes;

// ---------------------------------------------------------------- PLY

struct ParsedPly {
  std::vector<std::string> header;
  Mesh mesh;
  std::vector<uint8_t> face_counts;
  size_t trailing_bytes = 0;
};

template <typename T>
T take_le(const std::vector<unsigned char>& bytes, size_t& at) {
  std::array<unsigned char, sizeof(T)> b{};
  for (size_t i = 0; i < sizeof(T); ++i) b[i] = bytes.at(at + i);
  at += sizeof(T);
  if constexpr (std::endian::native == std::endian::big) std::reverse(b.begin(), b.end());
  return std::bit_cast<T>(b);
}

ParsedPly parse_ply(const std::string& path, size_t vertices, size_t faces) {
  const auto bytes = read_bytes(path);
  const std::string text(bytes.begin(), bytes.end());
  const std::string end = "end_header\n";
  const size_t body = text.find(end) + end.size();
  ParsedPly out;
  std::istringstream head(text.substr(0, body));
  for (std::string line; std::getline(head, line);) out.header.push_back(line);
  size_t at = body;
  for (size_t i = 0; i < vertices; ++i) {
    std::array<float, 3> p{};
    for (float& c : p) c = take_le<float>(bytes, at);
    out.mesh.positions.push_back(p);
  }
  for (size_t i = 0; i < faces; ++i) {
    out.face_counts.push_back(take_le<uint8_t>(bytes, at));
    std::array<uint32_t, 3> t{};
    for (uint32_t& v : t) v = static_cast<uint32_t>(take_le<int32_t>(bytes, at));
    out.mesh.triangles.push_back(t);
  }
  out.trailing_bytes = bytes.size() - at;
  return out;
}

TEST_F(MeshFormats, PlyWrittenParsesBackToTheSameMesh) {
  Mesh m;
  for (int i = 0; i < 70000; ++i) {  // more than one write block
    const float f = static_cast<float>(i);
    m.positions.push_back({f * 0.5f, -f, f / 3.0f});
  }
  for (uint32_t i = 0; i + 2 < 70000; i += 1) m.triangles.push_back({i, i + 2, i + 1});
  const std::string p = path("mesh.ply");
  write_ply(m, p);
  const ParsedPly ply = parse_ply(p, m.positions.size(), m.triangles.size());
  EXPECT_EQ(ply.header, (std::vector<std::string>{
                            "ply", "format binary_little_endian 1.0", "comment written by isotope",
                            "element vertex 70000", "property float x", "property float y", "property float z",
                            "element face 69998", "property list uchar int vertex_indices", "end_header"}));
  EXPECT_TRUE(ply.mesh.positions == m.positions);
  EXPECT_TRUE(ply.mesh.triangles == m.triangles);
  EXPECT_TRUE(std::all_of(ply.face_counts.begin(), ply.face_counts.end(), [](uint8_t c) { return c == 3; }));
  EXPECT_EQ(ply.trailing_bytes, 0u);
  EXPECT_EQ(entries(), (std::vector<std::string>{"mesh.ply"}));
}

TEST_F(MeshFormats, PlyOfAnEmptyMeshIsAValidHeaderOnly) {
  const std::string p = path("empty.ply");
  write_ply(Mesh{}, p);
  const ParsedPly ply = parse_ply(p, 0, 0);
  EXPECT_EQ(ply.header.at(3), "element vertex 0");
  EXPECT_EQ(ply.header.at(7), "element face 0");
  EXPECT_EQ(ply.trailing_bytes, 0u);
}

TEST_F(MeshFormats, PlyWithADanglingIndexIsRejectedAndNotWritten) {
  Mesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  m.triangles = {{0, 1, 2}, {0, 3, 1}};
  const std::string p = path("bad.ply");
  const std::string msg = io_error_of([&] { write_ply(m, p); });
  EXPECT_CONTAINS(msg, "triangle 1 references vertex 3");
  EXPECT_TRUE(entries().empty());
}

// Dangling indices in the middle and the last of three blocks of triangles (PLY checks its faces
// block by block as it writes them, the other formats all before): every format refuses the mesh,
// names the first, and leaves no file, on any number of threads.
TEST_F(MeshFormats, EveryFormatRefusesADanglingIndexInAnyBlockAndNamesTheFirst) {
  Mesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  m.triangles.assign(140000, {0, 1, 2});
  m.triangles[70000] = {0, 5, 1};
  m.triangles[139999] = {9, 0, 1};
  for (const size_t threads : {1, 2, 7}) {
    const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    for (const char* name : {"bad.ply", "bad.glb", "bad.vtp", "bad.stl", "bad.obj"}) {
      const std::string msg = io_error_of([&] { write_mesh(m, path(name)); });
      EXPECT_CONTAINS(msg, "triangle 70000 references vertex 5");
      EXPECT_TRUE(entries().empty()) << name << " on " << threads << " threads";
    }
  }
}

// The normals a GLB and a VTP carry are each vertex's own, at its place, on any thread count: the
// writers take them run by run from the threads that finish them (for_each_vertex_normals_run), on
// a mesh of several runs. glTF gives a vertex without a normal +z, VTK 0.
TEST_F(MeshFormats, GlbAndVtpCarryEveryVertexsNormalAtItsPlace) {
  const Mesh m = extract(generate_linked_tori(193), ExtractOptions{});
  const size_t n = m.positions.size();
  ASSERT_GT(n, 2 * kNormalsPerRun);
  const std::vector<std::array<float, 3>> expected = vertex_normals(m);
  const auto normals_at = [&](const std::vector<unsigned char>& bytes, size_t at) {
    std::vector<std::array<float, 3>> normals(n);
    for (auto& v : normals)
      for (float& c : v) c = take_le<float>(bytes, at);
    return normals;
  };
  for (const size_t threads : {1, 2, 7}) {
    const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    write_mesh(m, path("m.glb"));
    write_mesh(m, path("m.vtp"));
    // GLB: a 12-byte header, the JSON chunk (its length, its type, the text), the binary chunk's
    // length and type, then positions, normals and indices.
    const std::vector<unsigned char> glb = read_bytes(path("m.glb"));
    size_t at = 12;
    const size_t json = take_le<uint32_t>(glb, at);
    const std::vector<std::array<float, 3>> in_glb = normals_at(glb, 12 + 8 + json + 8 + 12 * n);
    // VTP: the appended data after "_": the normals' byte count, then the normals.
    const std::vector<unsigned char> vtp = read_bytes(path("m.vtp"));
    const std::string marker = "<AppendedData encoding=\"raw\">\n   _";
    const auto found = std::search(vtp.begin(), vtp.end(), marker.begin(), marker.end());
    ASSERT_NE(found, vtp.end());
    at = static_cast<size_t>(found - vtp.begin()) + marker.size();
    EXPECT_EQ(take_le<uint64_t>(vtp, at), 12 * n);
    const std::vector<std::array<float, 3>> in_vtp = normals_at(vtp, at);
    size_t glb_differ = 0, vtp_differ = 0;
    for (size_t i = 0; i < n; ++i) {
      const bool none = expected[i] == std::array<float, 3>{0, 0, 0};
      glb_differ += in_glb[i] != (none ? std::array<float, 3>{0, 0, 1} : expected[i]);
      vtp_differ += in_vtp[i] != expected[i];
    }
    EXPECT_EQ(glb_differ, 0u) << threads << " threads";
    EXPECT_EQ(vtp_differ, 0u) << threads << " threads";
  }
}

// ---------------------------------------------------------------- every format read back

// Minimal readers of what the writers make, enough to take the mesh back out of each format; the
// readers of other tools (the formats harness) check the formats as their users open them.

Mesh read_obj(const std::string& path) {
  Mesh m;
  std::ifstream in(path);
  for (std::string line; std::getline(in, line);) {
    std::istringstream fields(line);
    std::string tag;
    fields >> tag;
    if (tag == "v") {
      std::array<float, 3> p{};
      for (float& c : p) {
        std::string text;
        fields >> text;
        c = std::strtof(text.c_str(), nullptr);  // the shortest exact text: the same float
      }
      m.positions.push_back(p);
    } else if (tag == "f") {
      std::array<uint32_t, 3> t{};
      for (uint32_t& v : t) {
        int64_t one_based = 0;
        fields >> one_based;
        v = static_cast<uint32_t>(one_based - 1);
      }
      m.triangles.push_back(t);
    }
  }
  return m;
}

// STL keeps corners, not shared vertices: each triangle's three, in order.
std::vector<std::array<float, 9>> read_stl_corners(const std::string& path) {
  const std::vector<unsigned char> bytes = read_bytes(path);
  size_t at = 80;
  const auto count = take_le<uint32_t>(bytes, at);
  std::vector<std::array<float, 9>> out(count);
  for (auto& t : out) {
    at += 12;  // its normal
    for (float& c : t) c = take_le<float>(bytes, at);
    at += 2;  // the attribute byte count
  }
  EXPECT_EQ(at, bytes.size()) << path;
  return out;
}

// GLB through its JSON: the accessors of the primitive's POSITION and indices, where their buffer
// views put them in the binary chunk. Also returns the positions' min and max as the JSON states them.
Mesh read_glb(const std::string& path, std::array<float, 3>* min = nullptr, std::array<float, 3>* max = nullptr) {
  const std::vector<unsigned char> bytes = read_bytes(path);
  size_t at = 12;
  const auto json_bytes = take_le<uint32_t>(bytes, at);
  at += 4;  // the chunk's type
  const nlohmann::json gltf = nlohmann::json::parse(bytes.begin() + 20, bytes.begin() + 20 + json_bytes);
  const size_t bin = 20 + json_bytes + 8;
  Mesh m;
  if (!gltf.contains("meshes")) return m;
  const nlohmann::json& primitive = gltf["meshes"][0]["primitives"][0];
  const auto data = [&](const nlohmann::json& accessor) {
    const nlohmann::json& view = gltf["bufferViews"][accessor["bufferView"].get<size_t>()];
    return bin + view.value("byteOffset", size_t{0}) + accessor.value("byteOffset", size_t{0});
  };
  const nlohmann::json& position = gltf["accessors"][primitive["attributes"]["POSITION"].get<size_t>()];
  EXPECT_EQ(position["componentType"], 5126);  // FLOAT
  EXPECT_EQ(position["type"], "VEC3");
  at = data(position);
  m.positions.resize(position["count"].get<size_t>());
  for (auto& p : m.positions)
    for (float& c : p) c = take_le<float>(bytes, at);
  for (int a = 0; a < 3; ++a) {
    if (min) (*min)[static_cast<size_t>(a)] = position["min"][a].get<float>();
    if (max) (*max)[static_cast<size_t>(a)] = position["max"][a].get<float>();
  }
  const nlohmann::json& indices = gltf["accessors"][primitive["indices"].get<size_t>()];
  EXPECT_EQ(indices["componentType"], 5125);  // UNSIGNED_INT
  at = data(indices);
  m.triangles.resize(indices["count"].get<size_t>() / 3);
  for (auto& t : m.triangles)
    for (uint32_t& v : t) v = take_le<uint32_t>(bytes, at);
  return m;
}

// VTP's appended data: each array at its offset past "_", a UInt64 byte count, then its values.
Mesh read_vtp(const std::string& path) {
  const std::vector<unsigned char> bytes = read_bytes(path);
  const std::string text(bytes.begin(), bytes.end());
  const std::string marker = "<AppendedData encoding=\"raw\">\n   _";
  const size_t appended = text.find(marker) + marker.size();
  const auto array_at = [&](const std::string& name) {
    const size_t tag = text.find("Name=\"" + name + "\"");
    EXPECT_NE(tag, std::string::npos) << name;
    const size_t offset = text.find("offset=\"", tag) + 8;
    return appended + std::stoull(text.substr(offset, text.find('"', offset) - offset));
  };
  Mesh m;
  size_t at = array_at("Points");
  m.positions.resize(take_le<uint64_t>(bytes, at) / 12);
  for (auto& p : m.positions)
    for (float& c : p) c = take_le<float>(bytes, at);
  at = array_at("offsets");
  const size_t polys = take_le<uint64_t>(bytes, at) / 4;
  for (size_t i = 0; i < polys; ++i) EXPECT_EQ(take_le<int32_t>(bytes, at), static_cast<int32_t>(3 * (i + 1)));
  at = array_at("connectivity");
  m.triangles.resize(take_le<uint64_t>(bytes, at) / 12);
  for (auto& t : m.triangles)
    for (uint32_t& v : t) v = static_cast<uint32_t>(take_le<int32_t>(bytes, at));
  return m;
}

TEST_F(MeshFormats, EveryFormatHoldsTheSameMeshReadBack) {
  const Mesh m = extract(generate_linked_tori(33), ExtractOptions{});
  ASSERT_GT(m.triangles.size(), 1000u);
  for (const char* name : {"m.obj", "m.stl", "m.glb", "m.vtp"}) write_mesh(m, path(name));
  const auto same = [&](const Mesh& read, const char* name) {
    EXPECT_TRUE(std::equal(m.positions.begin(), m.positions.end(), read.positions.begin(), read.positions.end()))
        << name << ": positions";
    EXPECT_TRUE(std::equal(m.triangles.begin(), m.triangles.end(), read.triangles.begin(), read.triangles.end()))
        << name << ": triangles";
  };
  same(read_obj(path("m.obj")), "OBJ");
  same(read_vtp(path("m.vtp")), "VTP");
  std::array<float, 3> min{}, max{};
  same(read_glb(path("m.glb"), &min, &max), "GLB");
  for (size_t a = 0; a < 3; ++a) {
    const auto [lo, hi] = std::minmax_element(m.positions.begin(), m.positions.end(),
                                              [&](const auto& p, const auto& q) { return p[a] < q[a]; });
    EXPECT_EQ(min[a], (*lo)[a]) << "GLB min, axis " << a;
    EXPECT_EQ(max[a], (*hi)[a]) << "GLB max, axis " << a;
  }
  const std::vector<std::array<float, 9>> corners = read_stl_corners(path("m.stl"));
  ASSERT_EQ(corners.size(), m.triangles.size());
  size_t differ = 0;
  for (size_t t = 0; t < corners.size(); ++t)
    for (size_t k = 0; k < 3; ++k)
      for (size_t c = 0; c < 3; ++c) differ += corners[t][3 * k + c] != m.positions[m.triangles[t][k]][c];
  EXPECT_EQ(differ, 0u) << "STL corners";
}

TEST_F(MeshFormats, AnEmptyMeshReadsBackEmptyFromEveryFormat) {
  const Mesh empty;
  for (const char* name : {"e.obj", "e.stl", "e.glb", "e.vtp"}) write_mesh(empty, path(name));
  const Mesh obj = read_obj(path("e.obj"));
  EXPECT_TRUE(obj.positions.empty() && obj.triangles.empty());
  EXPECT_TRUE(read_stl_corners(path("e.stl")).empty());
  // GLB: its stated length the file's, one JSON chunk and no binary one, a scene without meshes.
  const std::vector<unsigned char> glb = read_bytes(path("e.glb"));
  size_t at = 8;
  EXPECT_EQ(take_le<uint32_t>(glb, at), glb.size());
  const auto json_bytes = take_le<uint32_t>(glb, at);
  EXPECT_EQ(take_le<uint32_t>(glb, at), 0x4E4F534Au);  // "JSON"
  EXPECT_EQ(20 + json_bytes, glb.size());
  EXPECT_FALSE(nlohmann::json::parse(glb.begin() + 20, glb.end()).contains("meshes"));
  const Mesh vtp = read_vtp(path("e.vtp"));
  EXPECT_TRUE(vtp.positions.empty() && vtp.triangles.empty());
}

}  // namespace
}  // namespace isotope
