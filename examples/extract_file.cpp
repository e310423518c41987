// From a file to a mesh: extract_file VOLUME ISO MESH.ply [EPS]. VOLUME is anything isotope reads
// (NAME_XxYxZ_TYPE.raw, FILE.h5:/dataset, .nrrd, a store made by `isotope convert`).
#include <cstdio>
#include <cstdlib>

#include <isotope/isotope.h>

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
    std::printf("%s: %lld triangles, %lld components, Euler characteristic %lld\n", argv[3],
                static_cast<long long>(t.triangles), static_cast<long long>(t.components),
                static_cast<long long>(t.euler_characteristic));
  } catch (const std::exception& e) {  // isotope::IoError for a file's trouble, OptionError for options
    std::fprintf(stderr, "extract_file: %s\n", e.what());
    return 1;
  }
}
