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
  if (static_cast<int64_t>(volume.values.size()) != volume.node_count())
    throw std::invalid_argument("volume holds " + std::to_string(volume.values.size()) +
                                " values, its dimensions need " + std::to_string(volume.node_count()));
  for (size_t i = 0; i < volume.values.size(); ++i)
    if (!std::isfinite(volume.values[i]))
      throw std::invalid_argument("volume value " + std::to_string(i) + " is not finite");
}

// Nodes beyond the data box replicate the nearest data node: ranges stay tight, and no diamond
// that reaches past the box is ever stopped at (its error is infinite), so these values are
// never interpolated into the mesh (design.md, "Volumes that are not (2^k+1)^3").
std::vector<float> embed(const Volume& volume, const Lattice& lattice) {
  std::vector<float> values(static_cast<size_t>(lattice.node_count()));
  tbb::parallel_for(int64_t{0}, lattice.side, [&](int64_t z) {
    const int64_t sz = std::min(z, volume.dims[2] - 1);
    for (int64_t y = 0; y < lattice.side; ++y) {
      const int64_t sy = std::min(y, volume.dims[1] - 1);
      for (int64_t x = 0; x < lattice.side; ++x)
        values[static_cast<size_t>(lattice.index(x, y, z))] = volume.at(std::min(x, volume.dims[0] - 1), sy, sz);
    }
  });
  return values;
}

struct Counters {
  std::atomic<int64_t> paper[3] = {0, 0, 0}, exact[3] = {0, 0, 0};
};

class RecordBuilder {
 public:
  RecordBuilder(const Lattice& lattice, const std::array<int64_t, 3>& dims, const std::vector<float>& values,
                std::vector<DiamondRecord>& records)
      : lattice_(lattice), dims_(dims), values_(values), records_(records) {}

  // Computes v's record from its polyhedron and the (already final) records of its children.
  void build(const Coord& v, int64_t local_counts[2][3]) const {
    const Diamond d = diamond_of(v, lattice_);
    DiamondValues dv;
    dv.type = d.type;
    dv.fa = value(d.a);
    dv.fb = value(d.b);
    dv.fv = value(d.v);
    bool inside_box = in_box(d.a) && in_box(d.b);
    float lo = std::min({dv.fa, dv.fb, dv.fv}), hi = std::max({dv.fa, dv.fb, dv.fv});
    for (int i = 0; i < d.ring_count; ++i) {
      const bool real = lattice_.contains(d.ring[i]);
      dv.ring[i] = value(real ? d.ring[i] : mirror_into(d.ring[i], lattice_));
      if (!real) continue;
      inside_box = inside_box && in_box(d.ring[i]);
      lo = std::min(lo, dv.ring[i]);
      hi = std::max(hi, dv.ring[i]);
    }

    DiamondRecord rec;
    double child_bound = 0;
    float child_surplus = 0;
    IsoInterval exact_bar, paper_bar;
    float weight = 0;
    if (d.level + 1 < lattice_.max_level()) {  // else the children are leaves, with no record
      for (int i = 0; i < d.ring_count; ++i) {
        const Coord& p = d.ring[i];
        const Coord& q = d.ring[(i + 1) % d.ring_count];
        if (!lattice_.contains(p) || !lattice_.contains(q)) continue;  // a missing tet of a cut diamond
        for (const Coord& end : {d.a, d.b}) {
          const DiamondRecord& c = record(longest_edge_midpoint({end, d.v, p, q}));
          child_bound = std::max(child_bound, static_cast<double>(c.error_bound));
          child_surplus = std::max(child_surplus, c.error_surplus);
          lo = std::min(lo, c.lo);
          hi = std::max(hi, c.hi);
          exact_bar.hull({c.exact_lo, c.exact_hi});
          paper_bar.hull({c.paper_lo, c.paper_hi});
          weight = std::max(weight, c.weight);
        }
      }
    }
    rec.lo = lo;
    rec.hi = hi;
    if (!inside_box) {
      rec.error_bound = rec.error_surplus = kInfinity;
    } else {
      const double eta = std::fabs(static_cast<double>(dv.fv) - 0.5 * (static_cast<double>(dv.fa) + dv.fb));
      rec.error_bound = round_up(eta + child_bound);
      rec.error_surplus = std::max(round_up(eta), child_surplus);
      const IsoInterval exact = exact_interval(dv);
      const IsoInterval paper = paper_interval(dv);
      local_counts[0][static_cast<int>(d.type)] += paper.empty() ? 0 : 1;
      local_counts[1][static_cast<int>(d.type)] += exact.empty() ? 0 : 1;
      exact_bar.hull(exact);
      paper_bar.hull(paper);
      weight = std::max(weight, exact.length());
    }
    if (!exact_bar.empty()) { rec.exact_lo = exact_bar.lo; rec.exact_hi = exact_bar.hi; }
    if (!paper_bar.empty()) { rec.paper_lo = paper_bar.lo; rec.paper_hi = paper_bar.hi; }
    rec.weight = weight;
    records_[static_cast<size_t>(lattice_.index(v))] = rec;
  }

 private:
  float value(const Coord& c) const { return values_[static_cast<size_t>(lattice_.index(c))]; }
  const DiamondRecord& record(const Coord& c) const { return records_[static_cast<size_t>(lattice_.index(c))]; }
  bool in_box(const Coord& c) const { return c[0] < dims_[0] && c[1] < dims_[1] && c[2] < dims_[2]; }

  const Lattice& lattice_;
  const std::array<int64_t, 3>& dims_;
  const std::vector<float>& values_;
  std::vector<DiamondRecord>& records_;
};

}  // namespace

MultiresVolume MultiresVolume::build(const Volume& volume) {
  const auto start = std::chrono::steady_clock::now();
  validate(volume);
  MultiresVolume mv;
  mv.lattice_ = Lattice::enclosing(volume.dims);
  mv.data_dims_ = volume.dims;
  mv.spacing_ = volume.spacing;
  mv.origin_ = volume.origin;
  mv.values_ = embed(volume, mv.lattice_);
  mv.records_.resize(static_cast<size_t>(mv.lattice_.node_count()));

  const Lattice& lat = mv.lattice_;
  const RecordBuilder builder(lat, mv.data_dims_, mv.values_, mv.records_);
  Counters counters;
  // Bottom-up, level by level (paper Sec. 3.2): scale j = 0 is the finest, and within a scale
  // edge midpoints (m = 1) are finer than face centres (m = 2), which are finer than cube centres.
  for (int j = 0; j < lat.k; ++j) {
    const int64_t h = int64_t{1} << j;
    for (int m = 1; m <= 3; ++m) {
      tbb::parallel_for(int64_t{0}, lat.n / h + 1, [&](int64_t zi) {
        int64_t counts[2][3] = {{0, 0, 0}, {0, 0, 0}};
        const int64_t z = zi * h;
        const int oz = (z / h) & 1;
        for (int64_t y = 0; y <= lat.n; y += h) {
          const int oy = (y / h) & 1;
          for (int64_t x = 0; x <= lat.n; x += h) {
            const int ox = (x / h) & 1;  // odd multiple of h: exactly j trailing zeros
            if (ox + oy + oz == m) builder.build({x, y, z}, counts);
          }
        }
        for (int t = 0; t < 3; ++t) {
          counters.paper[t] += counts[0][t];
          counters.exact[t] += counts[1][t];
        }
      });
    }
  }
  for (int t = 0; t < 3; ++t) {
    mv.stats_.critical_paper[t] = counters.paper[t];
    mv.stats_.critical_exact[t] = counters.exact[t];
  }
  mv.stats_.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return mv;
}

}  // namespace isotope
