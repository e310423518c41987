#include "engine/extract/extract_drivers.h"

#include <algorithm>
#include <cassert>
#include <chrono>
#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

#include "engine/core/parallel.h"
#include "engine/extract/adaptive_extract.h"
#include "engine/extract/array_source.h"
#include "engine/hierarchy/hierarchy.h"
#include "isotope/error.h"

namespace isotope {
namespace {

// MultiresVolume as a traversal source (the TraversalSource concept).
class InMemory {
 public:
  explicit InMemory(const MultiresVolume& mv) : mv_(mv) {}
  const Lattice& lattice() const { return mv_.lattice(); }
  const std::array<int64_t, 3>& data_dims() const { return mv_.data_dims(); }
  const std::array<double, 3>& origin() const { return mv_.origin(); }
  const std::array<double, 3>& spacing() const { return mv_.spacing(); }
  double value_offset() const { return mv_.value_offset(); }
  double value_scale() const { return mv_.value_scale(); }
  double error_fold() const { return 0; }

  class Reader {
   public:
    explicit Reader(const MultiresVolume& mv) : mv_(mv) {}
    float value(const Coord& c, int /*band*/) const { return mv_.value(c); }
    bool block_values(const Coord& lo, const std::array<int64_t, 3>& n, float* f, int64_t stride) const {
      for (int64_t z = 0; z <= n[2]; ++z)
        for (int64_t y = 0; y <= n[1]; ++y)
          mv_.value_row(lo[0], lo[1] + y, lo[2] + z, n[0] + 1, f + (z * stride + y) * stride);
      return true;
    }
    using Handle = int64_t;  // the record's slot
    Handle locate(traversal::Packed v) const {
      const Coord c = traversal::unpack(v);
      assert(mv_.has_record(c) && "the outside test keeps the traversal near the data box");
      return mv_.record_slot(c);
    }
    const DiamondBounds& bounds(Handle h, const RecordFields&) const { return mv_.bounds(h); }
    const DiamondTopology& topology(Handle h, const RecordFields&) const { return mv_.topology(h); }
    void prefetch(Handle h) const { __builtin_prefetch(&mv_.bounds(h)); }

   private:
    const MultiresVolume& mv_;
  };
  Reader reader() const { return Reader(mv_); }

 private:
  const MultiresVolume& mv_;
};

}  // namespace

bool needs_hierarchy(const ExtractOptions& options) {
  return options.eps != 0 || options.max_triangles > 0 || options.eps_ties >= 0;
}

bool budget_takes_full_resolution(const Volume& volume, const ExtractCall& options) {
  if (options.max_triangles <= 0 || options.auto_delta || options.distribution) return false;
  options.validate();
  return count_full_resolution_triangles(volume, options.iso) <= options.max_triangles;
}

namespace {

// An array's extraction, its options and values checked.
Mesh extract_checked(const Volume& volume, const ExtractCall& given, ExtractStats* stats,
                     const ProgressCallback& progress) {
  ExtractCall options = given;
  if (budget_takes_full_resolution(volume, options)) options.max_triangles = 0;
  const ArraySource source(volume);
  if (needs_hierarchy(options) || !finest_extract_applies(source.lattice()))
    return extract(Hierarchy::build(volume, fields_for(options), Hierarchy::kMemoryBrickBits, progress), options,
                   stats);
  const auto start = std::chrono::steady_clock::now();
  const traversal::SplitRule rule(options, source.lattice(), source.origin(), source.spacing());
  ExtractStats s;
  Mesh mesh = extract_finest(source, rule, &s);
  s.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (stats) *stats = s;
  return mesh;
}

}  // namespace

Mesh extract(const Volume& volume, const ExtractOptions& options, const RunContext& run, ExtractStats* stats) {
  options.validate();
  run.validate();
  validate_volume(volume);
  const ThreadLimit threads(run.threads);
  return extract_checked(volume, ExtractCall(options, run), stats, run.progress);
}

Mesh extract_validated(const Volume& volume, const ExtractCall& options, ExtractStats* stats,
                       const ProgressCallback& progress) {
  options.validate();
  return extract_checked(volume, options, stats, progress);
}

Mesh extract(const MultiresVolume& mv, const ExtractCall& options, ExtractStats* stats) {
  return extract_adaptive(InMemory(mv), options, stats);
}

Mesh extract(const Hierarchy& hierarchy, const ExtractCall& options, ExtractStats* stats, BudgetMemo* memo) {
  if (!hierarchy.fields().covers(fields_for(options)))
    throw InvalidInput("this hierarchy was built without the records topology mode " +
                       std::string(to_string(options.topology)) + " reads");
  return extract_adaptive(hierarchy, options, stats, std::nullopt, memo);
}

}  // namespace isotope
