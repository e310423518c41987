#include "engine/multires_volume.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "engine/critical_rule.h"
#include "engine/diamond.h"
#include "engine/parallel.h"

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
    DiamondBounds bounds;
    const bool inside_box = read_polyhedron(d, dv, bounds);
    Saturated sat;
    if (d.level + 1 < lattice_.max_level()) saturate_from_children(d, bounds, sat);  // else leaves, no record
    if (!inside_box) {
      // Refine always: its tetrahedra reach past the data box (design.md, "Volumes that are not
      // (2^k+1)^3"), so they are cut down to unit cells, each wholly inside or outside.
      bounds.error_bound = bounds.error_surplus = kInfinity;
    } else {
      const double eta = std::fabs(static_cast<double>(dv.fv) - 0.5 * (static_cast<double>(dv.fa) + dv.fb));
      bounds.error_bound = round_up(eta + sat.bound);
      bounds.error_surplus = std::max(round_up(eta), sat.surplus);
      const IsoInterval exact = exact_interval(dv);
      const IsoInterval paper = paper_interval(dv);
      counts[0][static_cast<int>(d.type)] += paper.empty() ? 0 : 1;
      counts[1][static_cast<int>(d.type)] += exact.empty() ? 0 : 1;
      sat.exact.hull(exact);
      sat.paper.hull(paper);
      sat.weight = std::max(sat.weight, exact.length());
    }
    store(v, bounds, sat);
  }

  void copy_values(const Volume& volume) const {
    parallel_for(int64_t{0}, volume.dims[2], [&](int64_t z) {
      for (int64_t y = 0; y < volume.dims[1]; ++y)
        for (int64_t x = 0; x < volume.dims[0]; ++x)
          mv_.values_[static_cast<size_t>(mv_.layout_.slot(x, y, z))] = volume.at(x, y, z);
    });
  }

 private:
  // What v inherits from the records of its children's refinement vertices.
  struct Saturated {
    double bound = 0;
    float surplus = 0;
    IsoInterval exact, paper;
    float weight = 0;
  };

  // Values at v's polyhedron (mirrored across the domain faces where the diamond is cut, paper
  // Sec. 4.3) and their range; true when every real vertex lies in the data box.
  bool read_polyhedron(const Diamond& d, DiamondValues& dv, DiamondBounds& bounds) const {
    dv.type = d.type;
    dv.fa = mv_.value(d.a);
    dv.fb = mv_.value(d.b);
    dv.fv = mv_.value(d.v);
    bool inside_box = in_box(d.a) && in_box(d.b);
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
    return inside_box;
  }

  // The children of tetrahedron (a, b, p, q) are (a, v, p, q) and (b, v, p, q), bisected at the
  // midpoint of `end` and the farther of p and q (checked by the hierarchy test). Far vertices
  // alternate around the ring, so each child is shared by two tetrahedra: visit each (end, far
  // ring vertex) pair once. A real far vertex always has a real tetrahedron.
  void saturate_from_children(const Diamond& d, DiamondBounds& bounds, Saturated& sat) const {
    for (const Coord* end : {&d.a, &d.b})
      for (int i = 0; i < d.ring_count; ++i) {
        const Coord& r = d.ring[i];
        if (squared_distance(*end, r) < squared_distance(*end, d.ring[(i + 1) % d.ring_count])) continue;
        if (!lattice_.contains(r)) continue;  // a missing tetrahedron of a cut diamond
        const Coord u{((*end)[0] + r[0]) / 2, ((*end)[1] + r[1]) / 2, ((*end)[2] + r[2]) / 2};
        // Without a record, u's whole diamond lies beyond a face of the data box: no data node
        // below it, and v, which reaches out there too, is refined anyway.
        if (!mv_.has_record(u)) continue;
        const int64_t c = mv_.record_slot(u);
        const DiamondBounds& cb = mv_.bounds(c);
        sat.bound = std::max(sat.bound, static_cast<double>(cb.error_bound));
        sat.surplus = std::max(sat.surplus, cb.error_surplus);
        bounds.lo = std::min(bounds.lo, cb.lo);
        bounds.hi = std::max(bounds.hi, cb.hi);
        const DiamondTopology& ct = mv_.topology(c);
        sat.exact.hull({ct.exact_lo, ct.exact_hi});
        sat.paper.hull({ct.paper_lo, ct.paper_hi});
        sat.weight = std::max(sat.weight, ct.weight);
      }
  }

  void store(const Coord& v, const DiamondBounds& bounds, const Saturated& sat) const {
    const int64_t s = mv_.record_slot(v);
    mv_.bounds_[static_cast<size_t>(s)] = bounds;
    DiamondTopology& topo = mv_.topology_[static_cast<size_t>(s)];
    if (!sat.exact.empty()) { topo.exact_lo = sat.exact.lo; topo.exact_hi = sat.exact.hi; }
    if (!sat.paper.empty()) { topo.paper_lo = sat.paper.lo; topo.paper_hi = sat.paper.hi; }
    topo.weight = sat.weight;
  }

  bool in_box(const Coord& c) const {
    return c[0] < mv_.data_dims_[0] && c[1] < mv_.data_dims_[1] && c[2] < mv_.data_dims_[2];
  }

  MultiresVolume& mv_;
  const Lattice& lattice_;
};

MultiresVolume MultiresVolume::build(const Volume& volume, const ProgressCallback& progress) {
  const auto start = std::chrono::steady_clock::now();
  validate(volume);
  MultiresVolume mv;
  mv.lattice_ = Lattice::enclosing(volume.dims);
  mv.data_dims_ = volume.dims;
  mv.spacing_ = volume.spacing;
  mv.origin_ = volume.origin;
  // Lattice nodes beyond the data box are never stored: value() answers with the nearest data
  // node, which keeps ranges tight, and no diamond that reaches past the box is ever stopped at,
  // so those values never reach the mesh (design.md, "Volumes that are not (2^k+1)^3").
  mv.layout_ = BrickLayout(volume.dims);
  mv.values_.resize(static_cast<size_t>(mv.layout_.size));
  int64_t records = 0;
  std::vector<std::array<int64_t, 3>> scale_nodes;
  for (int j = 0; j <= mv.lattice_.k; ++j) {
    scale_nodes.push_back({(mv.record_extent(0, j) >> j) + 1, (mv.record_extent(1, j) >> j) + 1,
                           (mv.record_extent(2, j) >> j) + 1});
    mv.scale_layout_.emplace_back(scale_nodes.back());
    mv.scale_offset_.push_back(records);
    records += mv.scale_layout_.back().size;
  }
  mv.bounds_.resize(static_cast<size_t>(records));
  mv.topology_.resize(static_cast<size_t>(records));

  const RecordBuilder builder(mv);
  builder.copy_values(volume);
  int64_t work = 0;  // nodes of each scale that are not all-even there, i.e. not coarser
  for (int j = 0; j < mv.lattice_.k; ++j) {
    const auto& n = scale_nodes[static_cast<size_t>(j)];
    work += n[0] * n[1] * n[2] - (n[0] + 1) / 2 * ((n[1] + 1) / 2) * ((n[2] + 1) / 2);
  }
  ProgressReporter reporter(progress, work);
  std::atomic<int64_t> paper[3] = {0, 0, 0}, exact[3] = {0, 0, 0};
  // Bottom-up, level by level (paper Sec. 3.2): scale j = 0 is the finest, and within a scale
  // edge midpoints (m = 1) are finer than face centres (m = 2), which are finer than cube centres.
  // In units of 2^j, a node of scale j has m odd coordinates. Nodes are visited brick by brick
  // of their scale's layout, so the children's records a node reads are close by.
  constexpr int64_t kWidth = int64_t{1} << BrickLayout::kBits;
  for (int j = 0; j < mv.lattice_.k; ++j) {
    const std::array<int64_t, 3> nodes = scale_nodes[static_cast<size_t>(j)];
    const int64_t bx = (nodes[0] + kWidth - 1) / kWidth, by = (nodes[1] + kWidth - 1) / kWidth,
                  bz = (nodes[2] + kWidth - 1) / kWidth;
    for (int m = 1; m <= 3; ++m) {
      parallel_for(int64_t{0}, bz * by, [&](int64_t bzy) {
        int64_t counts[2][3] = {{0, 0, 0}, {0, 0, 0}};
        int64_t built = 0;
        const int64_t z0 = bzy / by * kWidth, y0 = bzy % by * kWidth;
        for (int64_t x0 = 0; x0 < bx * kWidth; x0 += kWidth)
          for (int odd = 0; odd < 8; ++odd) {  // which of x, y, z are odd (in units of 2^j)
            const int ox = odd & 1, oy = (odd >> 1) & 1, oz = odd >> 2;
            if (ox + oy + oz != m) continue;
            for (int64_t z = z0 + oz; z < std::min(z0 + kWidth, nodes[2]); z += 2)
              for (int64_t y = y0 + oy; y < std::min(y0 + kWidth, nodes[1]); y += 2)
                for (int64_t x = x0 + ox; x < std::min(x0 + kWidth, nodes[0]); x += 2, ++built)
                  builder.build({x << j, y << j, z << j}, counts);
          }
        for (int t = 0; t < 3; ++t) {
          paper[t] += counts[0][t];
          exact[t] += counts[1][t];
        }
        reporter.advance(built);
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
