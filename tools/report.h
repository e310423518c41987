#pragma once
// What one extraction produced, as a JSON report (extract --report) and a one-line summary.
#include <array>
#include <cstdint>
#include <nlohmann/json_fwd.hpp>
#include <string>

#include "engine/extract.h"
#include "engine/mesh_topology.h"
#include "engine/multires_volume.h"
#include "engine/options.h"

namespace isotope::tools {

struct ExtractionRun {
  std::string input;
  std::string output;
  ExtractOptions options;
  std::array<int64_t, 3> data_dims{0, 0, 0};
  int lattice_k = 0;
  PreprocessStats preprocess;
  ExtractStats extract;
  MeshTopology topology;
  double read_seconds = 0, preprocess_seconds = 0, extract_seconds = 0, measure_seconds = 0;
  double total_seconds() const { return read_seconds + preprocess_seconds + extract_seconds + measure_seconds; }
};

// The report: the counts the issue asks for at top level, then inputs, timings, engine stats.
nlohmann::ordered_json report_json(const ExtractionRun& run);
// "MESH.ply: 1234 triangles, 620 vertices, 1 component, chi 2, ..." for stdout.
std::string summary_line(const ExtractionRun& run);
// Pretty-printed, atomically (temporary file + rename); throws IoError.
void write_json_file(const nlohmann::ordered_json& json, const std::string& path);

}  // namespace isotope::tools
