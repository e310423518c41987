#pragma once
// isotope: multiresolution isosurface extraction with topology control (Gerstner & Pajarola,
// IEEE Visualization 2000), out of core, on all cores. The public interface, whole:
//
//   isotope/volume.h   Volume (an array in memory), ScalarType
//   isotope/mesh.h     Mesh, MeshTopology, measure_topology, vertex_normals, write_ply, write_mesh
//   isotope/extract.h  ExtractOptions (iso, eps, topology, ...), ExtractStats, extract(Volume)
//   isotope/source.h   open_volume(): any input (raw, NRRD, HDF5, a store, an array), extracted
//                      from as often as needed
//   isotope/convert.h  convert(): a volume into a store, for extraction out of core
//   isotope/run_context.h  RunContext: how a call runs (threads, cancel, progress, processes),
//                      apart from what it computes
//   isotope/error.h    isotope::Error and its kinds (OptionError, InvalidInput, IoError, ...)
//   isotope/progress.h ProgressCallback, what a long step reports to
//   isotope/distribution.h  Distribution: one extraction or convert spread over processes
//
// examples/ holds three programs: from a file, from an array, and out of core (a convert within a
// memory budget, with progress and cancellation, then extractions from the store).
//
// Ten lines from a file to a mesh (examples/extract_file.cpp):
//
//   #include <isotope/isotope.h>
//   int main() {
//     isotope::Source ct = isotope::open_volume({"embryo_256x256x256_uint8.raw"});
//     isotope::ExtractOptions o;
//     o.iso = 64.5f;
//     o.eps = 16;                                  // data units: the coarse surface's error bound
//     isotope::Mesh mesh = ct.extract(o);           // topology kept (o.topology = preserve)
//     isotope::write_ply(mesh, "embryo.ply");
//   }
//
// CMake: find_package(isotope CONFIG REQUIRED) and target_link_libraries(app isotope::isotope).
// Everything else in this repository (engine/, io/) is a detail that may change.
#include <isotope/convert.h>
#include <isotope/distribution.h>
#include <isotope/error.h>
#include <isotope/extract.h>
#include <isotope/mesh.h>
#include <isotope/progress.h>
#include <isotope/run_context.h>
#include <isotope/source.h>
#include <isotope/version.h>
#include <isotope/volume.h>
