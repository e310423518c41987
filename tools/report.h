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
#include "io/brick_cache.h"

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
  int threads = 1;
  double peak_rss_mb = 0;
  BrickCacheStats cache;        // store input: what the brick cache read and served
  int64_t cache_mb = 0;         // store input: its budget (0: not a store)
  uint64_t cache_budget_bytes = 0;  // store input: the budget in effect (BrickCache::kMinBricks)
  uint64_t store_bytes = 0;     // store input: the file's size
  uint64_t input_bytes = 0;     // other input: the values read (as float)
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
