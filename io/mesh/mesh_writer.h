#pragma once
// The mesh formats users open, chosen by the output's extension (docs/MESH_FORMATS.md):
//   .ply  binary little-endian PLY: float x,y,z per vertex; uchar-counted int indices per face
//   .obj  Wavefront OBJ text: "v x y z" and 1-based "f a b c" (MeshLab, Blender)
//   .stl  binary STL: per triangle its unit normal and three corners (3-D printing, CAD)
//   .glb  glTF 2.0 binary: positions, unit vertex normals, uint32 indices (browsers, Blender)
//   .vtp  VTK XML PolyData, raw appended binary: points, normals, polys (ParaView)
// Every format is written through AtomicFile (its output policy): complete or not at all.
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "io/file/atomic_file.h"
#include "isotope/mesh.h"

namespace isotope {

enum class MeshFormat { ply, obj, stl, glb, vtp };

// The format PATH's extension names (case-insensitive); nullopt for any other extension.
std::optional<MeshFormat> mesh_format_of(const std::string& path);
// "PATH: unknown mesh format '.EXT' (use .ply, .obj, .stl, .glb or .vtp)": what every face says.
std::string unknown_mesh_format_message(const std::string& path);

// Written to a temporary file beside PATH and renamed when complete; throws IoError.
void write_ply(const Mesh& mesh, const std::string& path);
// Writes and finishes OUT (AtomicFile::finish) without committing it: the caller renames it into
// place together with its other outputs.
void write_ply(const Mesh& mesh, AtomicFile& out);
void write_mesh(const Mesh& mesh, AtomicFile& out, MeshFormat format);

// A parallel VTK PolyData file (.pvtp) naming `pieces` (.vtp files, relative to its folder) that
// ParaView and VTK's vtkXMLPPolyDataReader open as one dataset: a distributed extraction's
// parts (isotope extract --parts, docs/DISTRIBUTED.md). Written atomically; throws IoError.
void write_pvtp(const std::vector<std::string>& pieces, const std::string& path);

}  // namespace isotope
