// Opening an input for extraction (tools/extraction_input.h).
#include "tools/extraction_input.h"

#include <malloc.h>

#include <CLI/CLI.hpp>
#include <chrono>
#include <cstdio>

#include "io/volume_reader.h"
#include "tools/commands.h"

namespace isotope::tools {

void keep_freed_brick_memory() {
  mallopt(M_MMAP_THRESHOLD, 64 << 20);
  mallopt(M_TRIM_THRESHOLD, 128 << 20);
}

ExtractionInput::ExtractionInput(const Spec& spec) {
  // A store is known by its magic; a file named .isotope without it is a damaged store, whose
  // reader says so, not a raw volume whose name lacks its dimensions (tests/reject/zeros.isotope).
  if (is_store_file(spec.path) || spec.path.ends_with(".isotope")) open_store(spec);
  else open_volume(spec);
}

void ExtractionInput::open_store(const Spec& spec) {
  if (!spec.dims.empty() || !spec.type.empty()) throw CLI::ValidationError("--dims/--type", "do not apply to a store");
  keep_freed_brick_memory();
  const auto start = std::chrono::steady_clock::now();
  store_ = std::make_unique<StoreReader>(spec.path);
  cache_ = std::make_unique<BrickCache>(*store_, static_cast<uint64_t>(spec.cache_mb) << 20);
  paged_ = std::make_unique<PagedVolume>(*cache_);
  read_seconds_ = seconds_since(start);
  cache_mb_ = spec.cache_mb;
  dims_ = store_->header().dims;
  spacing_ = store_->header().spacing;
}

void ExtractionInput::open_volume(const Spec& spec) {
  const auto start = std::chrono::steady_clock::now();
  VolumeSource source;
  source.spec = spec.path;
  if (!spec.dims.empty()) source.dims = parse_dims(spec.dims);
  if (!spec.type.empty()) source.type = parse_scalar_type(spec.type);
  volume_ = std::make_unique<Volume>(read_volume(source));
  read_seconds_ = seconds_since(start);
  dims_ = volume_->dims;
  spacing_ = volume_->spacing;
  input_bytes_ = volume_->values.size() * sizeof(float);
  progress_ = spec.progress;
  if (spec.progress) {
    std::fprintf(stderr, "isotope: read %lldx%lldx%lld volume in %.3f s\n", static_cast<long long>(dims_[0]),
                 static_cast<long long>(dims_[1]), static_cast<long long>(dims_[2]), read_seconds_);
  }
}

const Hierarchy& ExtractionInput::hierarchy(const RecordFields& fields) const {
  const std::lock_guard<std::mutex> lock(build_mutex_);
  if (memory_ && memory_->fields().covers(fields)) return *memory_;
  const RecordFields all = memory_ ? memory_->fields() | fields : fields;
  memory_.reset();
  const auto start = std::chrono::steady_clock::now();
  memory_ = std::make_unique<Hierarchy>(Hierarchy::build(*volume_, all, StoreLayout::kDefaultBrickBits,
                                                         progress_ ? progress_bar("preprocessing") : ProgressCallback{}));
  preprocess_seconds_ += seconds_since(start);
  if (progress_) {
    std::fprintf(stderr, "isotope: preprocessed (lattice %lld^3) in %.3f s\n",
                 static_cast<long long>(memory_->lattice().side), preprocess_seconds_);
  }
  return *memory_;
}

void ExtractionInput::prepare(const RecordFields& fields) const {
  if (volume_) hierarchy(fields);
}

Mesh ExtractionInput::extract(const ExtractOptions& options, ExtractStats* stats) const {
  if (paged_) return isotope::extract(*paged_, options, stats);
  if (!needs_hierarchy(options)) return isotope::extract(*volume_, options, stats);
  return isotope::extract(hierarchy(fields_for(options)), options, stats);
}

void ExtractionInput::describe(ExtractionRun& run) const {
  run.data_dims = dims_;
  run.spacing = spacing_;
  run.read_seconds = read_seconds_;
  run.preprocess_seconds = preprocess_seconds_;
  run.input_bytes = input_bytes_;
  if (volume_) {
    run.lattice_k = Lattice::enclosing(dims_).k;
    const std::lock_guard<std::mutex> lock(build_mutex_);
    if (memory_) run.preprocess = memory_->stats();
    run.hierarchy_built = memory_ != nullptr;
    return;
  }
  // A store was preprocessed by convert; its header keeps the critical-point counts.
  for (int t = 0; t < 3; ++t) {
    run.preprocess.critical_paper[t] = store_->header().critical_paper[t];
    run.preprocess.critical_exact[t] = store_->header().critical_exact[t];
  }
  run.lattice_k = paged_->lattice().k;
  run.cache = cache_->stats();
  run.cache_mb = cache_mb_;
  run.cache_budget_bytes = cache_->budget_bytes();
  run.cache_brick_bytes = cache_->brick_bytes();
  run.store_bytes = store_->file_bytes();
}

}  // namespace isotope::tools
