#pragma once
// Binary little-endian PLY: float x,y,z per vertex; uchar-counted int indices per face.
#include <string>

#include "engine/mesh.h"

namespace isotope {

// Written to a temporary file beside PATH and renamed when complete; throws IoError.
void write_ply(const Mesh& mesh, const std::string& path);

}  // namespace isotope
