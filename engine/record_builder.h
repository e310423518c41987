#pragma once
// One refinement vertex's saturated record (design.md, "Per-vertex record"), computed from the
// values at its polyhedron and the already final records of its children. Written once, used by
// the in-memory build (MultiresVolume) and by the banded out-of-core build (engine/band_tile.h),
// which therefore produce the same bits.
//
// Grid is where values and records live; it provides
//   const Lattice& lattice() const;  const std::array<int64_t, 3>& data_dims() const;
//   float value(const Coord&) const;            // any lattice node; beyond the data box, clamped
//   bool child(const Coord&, Record&) const;    // false where no record exists
//   void store(const Coord&, const Record&);
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

#include "engine/critical_rule.h"
#include "engine/diamond.h"
#include "engine/record.h"

namespace isotope {

// Smallest float >= d, so that stored errors never under-state the exact ones.
inline float round_up(double d) {
  float f = static_cast<float>(d);
  if (static_cast<double>(f) < d) f = std::nextafter(f, std::numeric_limits<float>::infinity());
  return f;
}

// Per diamond type (cube, octahedron, diamond): how many vertices the paper's rule flags at
// f(v) ([0]) and where the exact rule fires for some isovalue ([1]).
using CriticalCounts = int64_t[2][3];

// What a vertex inherits from the records of its children's refinement vertices.
struct Saturation {
  double bound = 0;
  float surplus = 0;
  IsoInterval exact, paper;
  float weight = 0;

  // Folds in one child; its range widens the vertex's range `bounds`.
  void add(const Record& c, DiamondBounds& bounds) {
    bound = std::max(bound, static_cast<double>(c.bounds.error_bound));
    surplus = std::max(surplus, c.bounds.error_surplus);
    bounds.lo = std::min(bounds.lo, c.bounds.lo);
    bounds.hi = std::max(bounds.hi, c.bounds.hi);
    exact.hull({c.topology.exact_lo, c.topology.exact_hi});
    paper.hull({c.topology.paper_lo, c.topology.paper_hi});
    weight = std::max(weight, c.topology.weight);
  }
};

// The record from what was gathered: the polyhedron's values and range, whether every real
// polyhedron vertex lies in the data box, and the children's saturation.
inline Record finish_record(const DiamondValues& dv, bool inside_box, const DiamondBounds& range, Saturation sat,
                            CriticalCounts& counts) {
  Record r;
  r.bounds = range;
  if (!inside_box) {
    // Refine always: its tetrahedra reach past the data box (design.md, "Volumes that are not
    // (2^k+1)^3"), so they are cut down to unit cells, each wholly inside or outside.
    r.bounds.error_bound = r.bounds.error_surplus = std::numeric_limits<float>::infinity();
  } else {
    const double eta = std::fabs(static_cast<double>(dv.fv) - 0.5 * (static_cast<double>(dv.fa) + dv.fb));
    r.bounds.error_bound = round_up(eta + sat.bound);
    r.bounds.error_surplus = std::max(round_up(eta), sat.surplus);
    const IsoInterval exact = exact_interval(dv);
    const IsoInterval paper = paper_interval(dv);
    counts[0][static_cast<int>(dv.type)] += paper.empty() ? 0 : 1;
    counts[1][static_cast<int>(dv.type)] += exact.empty() ? 0 : 1;
    sat.exact.hull(exact);
    sat.paper.hull(paper);
    sat.weight = std::max(sat.weight, exact.length());
  }
  if (!sat.exact.empty()) { r.topology.exact_lo = sat.exact.lo; r.topology.exact_hi = sat.exact.hi; }
  if (!sat.paper.empty()) { r.topology.paper_lo = sat.paper.lo; r.topology.paper_hi = sat.paper.hi; }
  r.topology.weight = sat.weight;
  return r;
}

// Calls f(u) for the refinement vertex u of each child tetrahedron of v's diamond d. The
// children of tetrahedron (a, b, p, q) are (a, v, p, q) and (b, v, p, q), bisected at the
// midpoint of `end` and the farther of p and q (checked by the hierarchy test). Far vertices
// alternate around the ring, so each child is shared by two tetrahedra: each (end, far ring
// vertex) pair once. A real far vertex always has a real tetrahedron; leaves have no children.
template <class F>
void for_each_child(const Diamond& d, const Lattice& lattice, F f) {
  if (d.level + 1 >= lattice.max_level()) return;
  auto squared_distance = [](const Coord& p, const Coord& q) {
    int64_t s = 0;
    for (int a = 0; a < 3; ++a) s += (p[a] - q[a]) * (p[a] - q[a]);
    return s;
  };
  for (const Coord* end : {&d.a, &d.b})
    for (int i = 0; i < d.ring_count; ++i) {
      const Coord& r = d.ring[i];
      if (squared_distance(*end, r) < squared_distance(*end, d.ring[(i + 1) % d.ring_count])) continue;
      if (!lattice.contains(r)) continue;  // a missing tetrahedron of a cut diamond
      f(Coord{((*end)[0] + r[0]) / 2, ((*end)[1] + r[1]) / 2, ((*end)[2] + r[2]) / 2});
    }
}

template <class Grid>
class RecordBuilder {
 public:
  explicit RecordBuilder(Grid& grid) : grid_(grid), lattice_(grid.lattice()) {}

  void build(const Coord& v, CriticalCounts& counts) const {
    const Diamond d = diamond_of(v, lattice_);
    DiamondValues dv;
    DiamondBounds range;
    const bool inside_box = read_polyhedron(d, dv, range);
    Saturation sat;
    for_each_child(d, lattice_, [&](const Coord& u) {
      // Without a record, u's whole diamond lies beyond a face of the data box: no data node
      // below it, and v, which reaches out there too, is refined anyway.
      Record c;
      if (grid_.child(u, c)) sat.add(c, range);
    });
    grid_.store(v, finish_record(dv, inside_box, range, sat, counts));
  }

 private:
  // Values at v's polyhedron (mirrored across the domain faces where the diamond is cut, paper
  // Sec. 4.3) and their range; true when every real vertex lies in the data box.
  bool read_polyhedron(const Diamond& d, DiamondValues& dv, DiamondBounds& bounds) const {
    dv.type = d.type;
    dv.fa = grid_.value(d.a);
    dv.fb = grid_.value(d.b);
    dv.fv = grid_.value(d.v);
    bool inside_box = in_box(d.a) && in_box(d.b);
    bounds.lo = std::min({dv.fa, dv.fb, dv.fv});
    bounds.hi = std::max({dv.fa, dv.fb, dv.fv});
    for (int i = 0; i < d.ring_count; ++i) {
      const bool real = lattice_.contains(d.ring[i]);
      dv.ring[i] = grid_.value(real ? d.ring[i] : mirror_into(d.ring[i], lattice_));
      if (!real) continue;
      inside_box = inside_box && in_box(d.ring[i]);
      bounds.lo = std::min(bounds.lo, dv.ring[i]);
      bounds.hi = std::max(bounds.hi, dv.ring[i]);
    }
    return inside_box;
  }

  bool in_box(const Coord& c) const {
    const auto& dims = grid_.data_dims();
    return c[0] < dims[0] && c[1] < dims[1] && c[2] < dims[2];
  }

  Grid& grid_;
  const Lattice& lattice_;
};

}  // namespace isotope
