#pragma once
// Binary little-endian PLY: float x,y,z per vertex; uchar-counted int indices per face.
#include <string>

#include "io/file/atomic_file.h"
#include "isotope/mesh.h"

namespace isotope {

// Written to a temporary file beside PATH and renamed when complete; throws IoError.
void write_ply(const Mesh& mesh, const std::string& path);
// Writes and finishes OUT (AtomicFile::finish) without committing it: the caller renames it into
// place together with its other outputs.
void write_ply(const Mesh& mesh, AtomicFile& out);

}  // namespace isotope
