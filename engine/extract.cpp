#include "engine/extract.h"

#include <algorithm>
#include <cassert>
#include <chrono>
#include <cmath>
#include <stdexcept>
#include <vector>

#include "engine/adaptive_extract.h"
#include "engine/kuhn.h"
#include "engine/marching_tetrahedra.h"

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

using traversal::orientation;

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

Mesh extract_full_resolution(const Volume& volume, float iso) {
  if (!std::isfinite(iso)) throw std::invalid_argument("the isovalue must be a finite number");
  const auto& d = volume.dims;
  MeshBuilder builder(iso, std::max({d[0], d[1], d[2]}), volume.origin, volume.spacing);
  for (int64_t z = 0; z + 1 < d[2]; ++z)
    for (int64_t y = 0; y + 1 < d[1]; ++y)
      for (int64_t x = 0; x + 1 < d[0]; ++x) {
        int above = 0;
        for (int c = 0; c < 8; ++c) above += volume.at(x + (c & 1), y + ((c >> 1) & 1), z + (c >> 2)) > iso;
        if (above == 0 || above == 8) continue;
        for (const Tet& t : cell_tetrahedra({x, y, z}))
          builder.add_tet(t, {volume.at(t[0][0], t[0][1], t[0][2]), volume.at(t[1][0], t[1][1], t[1][2]),
                              volume.at(t[2][0], t[2][1], t[2][2]), volume.at(t[3][0], t[3][1], t[3][2])},
                          orientation(t) > 0);
      }
  return builder.take();
}

}  // namespace isotope
