// From a file to a mesh: extract_file VOLUME ISO MESH.ply [EPS]. VOLUME is anything isotope reads
// (NAME_XxYxZ_TYPE.raw, FILE.h5:/dataset, .nrrd, a store made by `isotope convert`).
#include <algorithm>
#include <array>
#include <cstdio>
#include <cstdlib>
#include <span>

#include <isotope/isotope.h>

// Code of one's own takes the mesh's arrays as views (pointer and count), as any contiguous data.
std::array<float, 6> bounding_box(std::span<const std::array<float, 3>> points) {
  std::array<float, 6> box{1e30f, 1e30f, 1e30f, -1e30f, -1e30f, -1e30f};
  for (const std::array<float, 3>& p : points)
    for (int a = 0; a < 3; ++a) box[a] = std::min(box[a], p[a]), box[3 + a] = std::max(box[3 + a], p[a]);
  return box;
}

int main(int argc, char** argv) {
  if (argc < 4) return std::fprintf(stderr, "usage: extract_file VOLUME ISO MESH.ply [EPS]\n"), 2;
  try {
    isotope::Source volume = isotope::open_volume({argv[1]});
    isotope::ExtractOptions o;
    o.iso = std::strtof(argv[2], nullptr);
    o.eps = argc > 4 ? std::strtod(argv[4], nullptr) : 0;  // data units; topology kept (preserve)
    isotope::Mesh mesh = volume.extract(o);
    isotope::write_ply(mesh, argv[3]);
    const isotope::MeshTopology t = isotope::measure_topology(mesh);
    const std::array<float, 6> b = bounding_box(mesh.vertices());
    std::printf("%s: %lld triangles, %lld components, Euler characteristic %lld, within (%g %g %g)-(%g %g %g)\n",
                argv[3], static_cast<long long>(t.triangles), static_cast<long long>(t.components),
                static_cast<long long>(t.euler_characteristic), b[0], b[1], b[2], b[3], b[4], b[5]);
  } catch (const std::exception& e) {  // isotope::IoError for a file's trouble, OptionError for options
    std::fprintf(stderr, "extract_file: %s\n", e.what());
    return 1;
  }
}
