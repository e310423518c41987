#pragma once
// What one extraction produced, as a JSON report (extract --report) and a one-line summary.
#include <array>
#include <cstdint>
#include <nlohmann/json_fwd.hpp>
#include <optional>
#include <string>
#include <vector>

#include "engine/diagnostics/component_report.h"
#include "engine/extract/extract_drivers.h"
#include "engine/extract/options.h"
#include "engine/hierarchy/multires_volume.h"
#include "io/store/brick_cache.h"
#include "isotope/mesh.h"
#include "isotope/source.h"

namespace isotope::tools {

struct ExtractionRun {
  std::string input;
  std::string output;
  ExtractOptions options;
  std::array<int64_t, 3> data_dims{0, 0, 0};
  std::array<double, 3> spacing{1, 1, 1};
  int lattice_k = 0;
  PreprocessStats preprocess;
  bool hierarchy_built = true;   // raw input at eps 0 needs none (isotope/source.h)
  bool critical_counted = true;  // not by a hierarchy built without its records' topology (SourceInfo)
  ExtractStats extract;
  MeshTopology topology;
  std::vector<ComponentStats> components;         // with --report
  std::optional<ComponentComparison> comparison;  // with --compare-full
  double compare_tolerance = 0;
  double compare_seconds = 0;  // --compare-full: the full-resolution extraction and the matching
  int threads = 1;
  double peak_rss_mb = 0;
  // A store's brick cache, or that of the store a volume's hierarchy was converted into.
  BrickCacheStats cache;            // what the brick cache read and served
  int64_t cache_mb = 0;             // its budget (0: no cache)
  uint64_t cache_budget_bytes = 0;  // the budget in effect (BrickCache::kMinBricks)
  uint64_t cache_brick_bytes = 0;   // a brick decoded whole, the cache's largest entry
  uint64_t store_bytes = 0;         // the store's size
  uint64_t input_bytes = 0;         // other input: the values read (as float)
  double read_seconds = 0, preprocess_seconds = 0, extract_seconds = 0, measure_seconds = 0;
  double total_seconds() const { return read_seconds + preprocess_seconds + extract_seconds + measure_seconds; }
};

// Fills what the run's report says of the input (SourceInfo, isotope/source.h): dimensions,
// spacing, lattice, preprocessing and its timings, and for a store, or a volume whose hierarchy
// went into a store of its own, the cache's budget and what it has read so far.
void describe(const SourceInfo& info, ExtractionRun& run);

// The report: the counts the issue asks for at top level, then inputs, timings, engine stats.
nlohmann::ordered_json report_json(const ExtractionRun& run);
// "MESH.ply: 1234 triangles, 620 vertices, 1 component, chi 2, ..." for stdout.
std::string summary_line(const ExtractionRun& run);
// "; 3 ranks, max/mean: cost 1.01, work 1.04, bytes read 1.10, time 1.05" for a distributed
// run's summary (isotope/distribution.h); empty for one process.
std::string balance_text(const std::vector<RankLoad>& loads);
// "against full resolution (12 components): 3 lost, 1 merged; 8 unchanged" for stdout.
std::string comparison_line(const ComponentComparison& c);
// Pretty-printed, atomically (temporary file + rename); throws IoError.
void write_json_file(const nlohmann::ordered_json& json, const std::string& path);

}  // namespace isotope::tools
