#include "engine/multires_volume.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include <tbb/parallel_for.h>

#include "engine/critical_rule.h"
#include "engine/diamond.h"

namespace isotope {
namespace {

constexpr float kInfinity = std::numeric_limits<float>::infinity();

// Smallest float >= d, so that stored errors never under-state the exact ones.
float round_up(double d) {
  float f = static_cast<float>(d);
  if (static_cast<double>(f) < d) f = std::nextafter(f, kInfinity);
  return f;
}

void validate(const Volume& volume) {
  for (int i = 0; i < 3; ++i)
    if (volume.dims[i] < 2)
      throw std::invalid_argument("volume dimensions must be at least 2 nodes per axis, got " +
                                  std::to_string(volume.dims[0]) + "x" + std::to_string(volume.dims[1]) +
                                  "x" + std::to_string(volume.dims[2]));
  for (int i = 0; i < 3; ++i)
    if (volume.dims[i] > (int64_t{1} << 19) + 1)  // the traversal packs coordinates in 21 bits
      throw std::invalid_argument("volume dimensions above 524289 nodes per axis are not supported");
  if (static_cast<int64_t>(volume.values.size()) != volume.node_count())
    throw std::invalid_argument("volume holds " + std::to_string(volume.values.size()) +
                                " values, its dimensions need " + std::to_string(volume.node_count()));
  for (size_t i = 0; i < volume.values.size(); ++i)
    if (!std::isfinite(volume.values[i]))
      throw std::invalid_argument("volume value " + std::to_string(i) + " is not finite");
}

int64_t squared_distance(const Coord& p, const Coord& q) {
  int64_t d = 0;
  for (int a = 0; a < 3; ++a) d += (p[a] - q[a]) * (p[a] - q[a]);
  return d;
}

}  // namespace

// Computes one refinement vertex's record from its polyhedron and the (already final)
// records of its children's refinement vertices.
class RecordBuilder {
 public:
  explicit RecordBuilder(MultiresVolume& mv) : mv_(mv), lattice_(mv.lattice_) {}

  void build(const Coord& v, int64_t counts[2][3]) const {
    const Diamond d = diamond_of(v, lattice_);
    DiamondValues dv;
    dv.type = d.type;
    dv.fa = mv_.value(d.a);
    dv.fb = mv_.value(d.b);
    dv.fv = mv_.value(d.v);
    bool inside_box = in_box(d.a) && in_box(d.b);
    DiamondBounds bounds;
    bounds.lo = std::min({dv.fa, dv.fb, dv.fv});
    bounds.hi = std::max({dv.fa, dv.fb, dv.fv});
    for (int i = 0; i < d.ring_count; ++i) {
      const bool real = lattice_.contains(d.ring[i]);
      dv.ring[i] = mv_.value(real ? d.ring[i] : mirror_into(d.ring[i], lattice_));
      if (!real) continue;
      inside_box = inside_box && in_box(d.ring[i]);
      bounds.lo = std::min(bounds.lo, dv.ring[i]);
      bounds.hi = std::max(bounds.hi, dv.ring[i]);
    }

    double child_bound = 0;
    float child_surplus = 0;
    IsoInterval exact_bar, paper_bar;
    float weight = 0;
    if (d.level + 1 < lattice_.max_level()) {  // else the children are leaves, with no record
      for (int i = 0; i < d.ring_count; ++i) {
        const Coord& p = d.ring[i];
        const Coord& q = d.ring[(i + 1) % d.ring_count];
        if (!lattice_.contains(p) || !lattice_.contains(q)) continue;  // a missing tet of a cut diamond
        for (const Coord* end : {&d.a, &d.b}) {
          // Child (end, v, p, q) is bisected at the midpoint of its longest edge, which in all
          // three polyhedra joins `end` to the farther of p and q (checked by the hierarchy test).
          const Coord& far = squared_distance(*end, p) > squared_distance(*end, q) ? p : q;
          const int64_t c = mv_.record_slot({((*end)[0] + far[0]) / 2, ((*end)[1] + far[1]) / 2, ((*end)[2] + far[2]) / 2});
          const DiamondBounds& cb = mv_.bounds(c);
          child_bound = std::max(child_bound, static_cast<double>(cb.error_bound));
          child_surplus = std::max(child_surplus, cb.error_surplus);
          bounds.lo = std::min(bounds.lo, cb.lo);
          bounds.hi = std::max(bounds.hi, cb.hi);
          const DiamondTopology& ct = mv_.topology(c);
          exact_bar.hull({ct.exact_lo, ct.exact_hi});
          paper_bar.hull({ct.paper_lo, ct.paper_hi});
          weight = std::max(weight, ct.weight);
        }
      }
    }
    if (!inside_box) {
      // Refine always: its tetrahedra reach past the data box (design.md, "Volumes that are not
      // (2^k+1)^3"), so they are cut down to unit cells, each wholly inside or outside.
      bounds.error_bound = bounds.error_surplus = kInfinity;
    } else {
      const double eta = std::fabs(static_cast<double>(dv.fv) - 0.5 * (static_cast<double>(dv.fa) + dv.fb));
      bounds.error_bound = round_up(eta + child_bound);
      bounds.error_surplus = std::max(round_up(eta), child_surplus);
      const IsoInterval exact = exact_interval(dv);
      const IsoInterval paper = paper_interval(dv);
      counts[0][static_cast<int>(d.type)] += paper.empty() ? 0 : 1;
      counts[1][static_cast<int>(d.type)] += exact.empty() ? 0 : 1;
      exact_bar.hull(exact);
      paper_bar.hull(paper);
      weight = std::max(weight, exact.length());
    }
    const int64_t s = mv_.record_slot(v);
    mv_.bounds_[static_cast<size_t>(s)] = bounds;
    DiamondTopology& topo = mv_.topology_[static_cast<size_t>(s)];
    if (!exact_bar.empty()) { topo.exact_lo = exact_bar.lo; topo.exact_hi = exact_bar.hi; }
    if (!paper_bar.empty()) { topo.paper_lo = paper_bar.lo; topo.paper_hi = paper_bar.hi; }
    topo.weight = weight;
  }

  // Nodes beyond the data box replicate the nearest data node: ranges stay tight, and no diamond
  // that reaches past the box is ever stopped at, so these values never reach the mesh.
  void embed(const Volume& volume) const {
    const Lattice& l = lattice_;
    tbb::parallel_for(int64_t{0}, l.side, [&](int64_t z) {
      const int64_t sz = std::min(z, volume.dims[2] - 1);
      for (int64_t y = 0; y < l.side; ++y) {
        const int64_t sy = std::min(y, volume.dims[1] - 1);
        for (int64_t x = 0; x < l.side; ++x)
          mv_.values_[static_cast<size_t>(mv_.layout_.slot(x, y, z))] = volume.at(std::min(x, volume.dims[0] - 1), sy, sz);
      }
    });
  }

 private:
  bool in_box(const Coord& c) const {
    return c[0] < mv_.data_dims_[0] && c[1] < mv_.data_dims_[1] && c[2] < mv_.data_dims_[2];
  }

  MultiresVolume& mv_;
  const Lattice& lattice_;
};

MultiresVolume MultiresVolume::build(const Volume& volume) {
  const auto start = std::chrono::steady_clock::now();
  validate(volume);
  MultiresVolume mv;
  mv.lattice_ = Lattice::enclosing(volume.dims);
  mv.layout_ = BrickLayout(mv.lattice_.side);
  mv.data_dims_ = volume.dims;
  mv.spacing_ = volume.spacing;
  mv.origin_ = volume.origin;
  mv.values_.resize(static_cast<size_t>(mv.layout_.size));
  int64_t records = 0;
  for (int j = 0; j <= mv.lattice_.k; ++j) {
    mv.scale_layout_.emplace_back((mv.lattice_.n >> j) + 1);
    mv.scale_offset_.push_back(records);
    records += mv.scale_layout_.back().size;
  }
  mv.bounds_.resize(static_cast<size_t>(records));
  mv.topology_.resize(static_cast<size_t>(records));

  const RecordBuilder builder(mv);
  builder.embed(volume);
  const Lattice& lat = mv.lattice_;
  std::atomic<int64_t> paper[3] = {0, 0, 0}, exact[3] = {0, 0, 0};
  // Bottom-up, level by level (paper Sec. 3.2): scale j = 0 is the finest, and within a scale
  // edge midpoints (m = 1) are finer than face centres (m = 2), which are finer than cube centres.
  // Nodes are visited brick by brick, so the children's records a node reads are close by.
  const int64_t bricks = mv.layout_.bricks_x, width = int64_t{1} << BrickLayout::kBits;
  for (int j = 0; j < lat.k; ++j) {
    const int64_t h = int64_t{1} << j;
    auto first = [h](int64_t b) { return (b + h - 1) / h * h; };  // first multiple of h >= b
    for (int m = 1; m <= 3; ++m) {
      tbb::parallel_for(int64_t{0}, bricks * bricks, [&](int64_t bzy) {
        int64_t counts[2][3] = {{0, 0, 0}, {0, 0, 0}};
        const int64_t z0 = bzy / bricks * width, y0 = bzy % bricks * width;
        for (int64_t x0 = 0; x0 < bricks * width; x0 += width)
          for (int64_t z = first(z0); z < std::min(z0 + width, lat.side); z += h)
            for (int64_t y = first(y0); y < std::min(y0 + width, lat.side); y += h)
              for (int64_t x = first(x0); x < std::min(x0 + width, lat.side); x += h) {
                // An odd multiple of h has exactly j trailing zeros.
                const int64_t odd = ((x >> j) & 1) + ((y >> j) & 1) + ((z >> j) & 1);
                if (odd == m) builder.build({x, y, z}, counts);
              }
        for (int t = 0; t < 3; ++t) {
          paper[t] += counts[0][t];
          exact[t] += counts[1][t];
        }
      });
    }
  }
  for (int t = 0; t < 3; ++t) {
    mv.stats_.critical_paper[t] = paper[t];
    mv.stats_.critical_exact[t] = exact[t];
  }
  mv.stats_.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return mv;
}

}  // namespace isotope
