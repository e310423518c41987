#include "engine/extract.h"

#include <cassert>
#include <chrono>
#include <cmath>
#include <stdexcept>
#include <vector>

#include "engine/adaptive_extract.h"

namespace isotope {
namespace {

// MultiresVolume as a traversal source (engine/traversal.h).
class InMemory {
 public:
  explicit InMemory(const MultiresVolume& mv) : mv_(mv) {}
  const Lattice& lattice() const { return mv_.lattice(); }
  const std::array<int64_t, 3>& data_dims() const { return mv_.data_dims(); }
  const std::array<double, 3>& origin() const { return mv_.origin(); }
  const std::array<double, 3>& spacing() const { return mv_.spacing(); }
  double value_offset() const { return mv_.value_offset(); }
  double value_scale() const { return mv_.value_scale(); }

  class RecordView {
   public:
    RecordView(const MultiresVolume& mv, int64_t slot) : mv_(mv), slot_(slot) {}
    const DiamondBounds& bounds() const { return mv_.bounds(slot_); }
    const DiamondTopology& topology() const { return mv_.topology(slot_); }

   private:
    const MultiresVolume& mv_;
    int64_t slot_;
  };
  class Reader {
   public:
    explicit Reader(const MultiresVolume& mv) : mv_(mv) {}
    float value(const Coord& c, int /*band*/) const { return mv_.value(c); }
    bool block_values(const Coord& lo, const std::array<int64_t, 3>& n, float* f, int64_t stride) const {
      for (int64_t z = 0; z <= n[2]; ++z)
        for (int64_t y = 0; y <= n[1]; ++y) mv_.value_row(lo[0], lo[1] + y, lo[2] + z, n[0] + 1, f + (z * stride + y) * stride);
      return true;
    }
    void prefetch(const Coord& v) const { __builtin_prefetch(&mv_.bounds(mv_.record_slot(v))); }
    RecordView record(const Coord& v) const {
      assert(mv_.has_record(v) && "the outside test keeps the traversal near the data box");
      return {mv_, mv_.record_slot(v)};
    }

   private:
    const MultiresVolume& mv_;
  };
  Reader reader() const { return Reader(mv_); }

 private:
  const MultiresVolume& mv_;
};

}  // namespace

void validate_extract_options(const ExtractOptions& o) {
  if (!std::isfinite(o.iso)) throw std::invalid_argument("the isovalue must be a finite number");
  if (!(o.eps >= 0)) throw std::invalid_argument("eps must be >= 0");
  if (!(o.delta >= 0)) throw std::invalid_argument("delta must be >= 0");
  if (o.delta > 0 && o.topology != TopologyMode::simplify)
    throw std::invalid_argument("delta applies to topology mode simplify only");
  if (o.max_triangles < 0) throw std::invalid_argument("the triangle budget must be >= 0");
  if (o.focus) {
    const Focus& f = *o.focus;
    if (!std::isfinite(f.point[0]) || !std::isfinite(f.point[1]) || !std::isfinite(f.point[2]))
      throw std::invalid_argument("the focus point must be finite");
    if (!(f.radius > 0) || !std::isfinite(f.radius)) throw std::invalid_argument("the focus radius must be > 0");
  }
}

Mesh extract(const MultiresVolume& mv, const ExtractOptions& options, ExtractStats* stats) {
  return extract_adaptive(InMemory(mv), options, stats);
}

}  // namespace isotope
