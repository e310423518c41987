#pragma once
// The viewer's files (viewer/: index.html, the esbuild bundle of viewer.js with three.js, the
// style), compiled into the isotope binary, so that `isotope serve` needs no install directory
// and reads no file by URL: a path is one of these names or nothing.
#include <optional>
#include <string_view>

namespace isotope::tools {

struct ViewerAsset {
  std::string_view bytes;
  const char* content_type;
};

// "/" and "/index.html", "/viewer.js", "/viewer.css"; nullopt for any other path.
std::optional<ViewerAsset> viewer_asset(std::string_view path);

}  // namespace isotope::tools
