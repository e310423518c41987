#pragma once
// A path's extension, lowercased ("SCAN.TIF" -> ".tif"): what chooses an input's reader
// (read_volume, is_tiff_stack) and an output mesh's format
// (mesh_format_of).
#include <algorithm>
#include <cctype>
#include <filesystem>
#include <string>

namespace isotope {

inline std::string lowercase_extension(const std::filesystem::path& path) {
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext;
}

}  // namespace isotope
