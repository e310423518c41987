#pragma once
// An input opened for extraction (`extract`, `sweep`): a store is paged through a brick cache, so
// that only the bricks a traversal reaches are read; any other volume is read into memory, and its
// hierarchy is built the first time an extraction needs one (eps > 0 or a triangle budget: at eps 0
// the array is marched as it is, engine/extract.h). Either way extract() can run many times.
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>

#include "engine/extract.h"
#include "engine/hierarchy.h"
#include "io/brick_cache.h"
#include "io/paged_volume.h"
#include "io/store_reader.h"
#include "tools/report.h"

namespace isotope::tools {

// The brick cache frees and allocates decoded bricks of a few fixed sizes all the time; glibc would
// return each to the kernel and fault fresh zeroed pages in for the next. This keeps them for
// reuse. Call before paging a store (process-wide).
void keep_freed_brick_memory();

class ExtractionInput {
 public:
  struct Spec {
    std::string path;
    std::string dims, type;  // raw input only: --dims, --type as typed ("" = from the file name)
    int64_t cache_mb = 512;  // store input only
    bool progress = false;   // read and preprocessing lines on stderr
  };
  // Throws CLI::ValidationError for --dims/--type on a store, IoError for unreadable input.
  explicit ExtractionInput(const Spec& spec);

  Mesh extract(const ExtractOptions& options, ExtractStats* stats = nullptr) const;
  // Builds now what extractions reading these fields will need (a volume's hierarchy), so that a
  // series of them builds it once (a store needs nothing).
  void prepare(const RecordFields& fields) const;
  // What the run's report says of the input: dimensions, spacing, lattice, preprocessing and its
  // timings, and for a store the cache's budget and what it has read so far.
  void describe(ExtractionRun& run) const;

 private:
  void open_store(const Spec& spec);
  void open_volume(const Spec& spec);
  // Built on first use, with the fields asked for; built again with more when a later extraction
  // reads more.
  const Hierarchy& hierarchy(const RecordFields& fields) const;

  std::unique_ptr<StoreReader> store_;
  std::unique_ptr<BrickCache> cache_;
  std::unique_ptr<PagedVolume> paged_;
  std::unique_ptr<Volume> volume_;
  mutable std::mutex build_mutex_;
  mutable std::unique_ptr<Hierarchy> memory_;
  bool progress_ = false;
  int64_t cache_mb_ = 0;
  std::array<int64_t, 3> dims_{0, 0, 0};
  std::array<double, 3> spacing_{1, 1, 1};
  uint64_t input_bytes_ = 0;
  double read_seconds_ = 0;
  mutable double preprocess_seconds_ = 0;
};

}  // namespace isotope::tools
