#pragma once
// One refinement vertex's saturated record (docs/METHOD.md, "Per-vertex records"), computed from the
// values at its polyhedron and the already final records of its children. Written once, used by
// the in-memory build (MultiresVolume) and by the banded out-of-core build (BandTile),
// which therefore produce the same bits.
//
// Grid is where values and records live; it provides
//   const Lattice& lattice() const;  const std::array<int64_t, 3>& data_dims() const;
//   float value(const Coord&) const;            // any lattice node; beyond the data box, clamped
//   bool child(const Coord&, Record&) const;    // false where no record exists
//   void store(const Coord&, const Record&);
#include <algorithm>
#include <array>
#include <bit>
#include <cassert>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <vector>
#if defined(__SSE2__)
#include <emmintrin.h>
#include <xmmintrin.h>
#endif

#include "engine/hierarchy/critical_rule.h"
#include "engine/hierarchy/diamond.h"
#include "engine/hierarchy/record.h"

namespace isotope {

// Smallest float >= d, so that stored errors never under-state the exact ones.
inline float round_up(double d) {
  float f = static_cast<float>(d);
  if (static_cast<double>(f) < d) {
    // The next float up: for the non-negative finite floats errors and weights are, the next bit
    // pattern (std::nextafter is a library call, and this runs for every record).
    f = f >= 0 && f < std::numeric_limits<float>::max() ? std::bit_cast<float>(std::bit_cast<uint32_t>(f) + 1)
                                                        : std::nextafter(f, std::numeric_limits<float>::infinity());
  }
  return f;
}

// A vertex's errors from its values and its children's (saturated) errors: eta, the distance of
// f(v) from the midpoint of its ends, added to the children's bound, and the larger of it and
// their surplus.
inline void vertex_errors(const DiamondValues& dv, float child_bound, float child_surplus, float& error_bound,
                          float& error_surplus) {
  const double eta = std::fabs(static_cast<double>(dv.fv) - 0.5 * (static_cast<double>(dv.fa) + dv.fb));
  error_bound = round_up(eta + static_cast<double>(child_bound));
  error_surplus = std::max(round_up(eta), child_surplus);
}

// Whether v lies strictly beyond both a and b: only then may either rule flag an isovalue
// (finish_record).
inline bool beyond_both_ends(const DiamondValues& dv) {
  return dv.fv < std::min(dv.fa, dv.fb) || dv.fv > std::max(dv.fa, dv.fb);
}

// Per diamond type (cube, octahedron, diamond): how many vertices the paper's rule flags at
// f(v) ([0]) and where the exact rule fires for some isovalue ([1]).
using CriticalCounts = int64_t[2][3];

// What a vertex inherits from the records of its children's refinement vertices.
struct Saturation {
  // The children's greatest bound as the float it is, widened once where it is summed (the
  // conversion is exact and monotone: the same double as a max taken over doubles).
  float bound = 0;
  float surplus = 0;
  IsoInterval exact, paper;
  std::array<float, 3> weight{0, 0, 0};

  // Folds in one child; its range widens the vertex's range `bounds`. Without `topology`, only
  // the range and errors (a store's band 0 read in mode none: PagedVolume).
  void add(const Record& c, DiamondBounds& bounds, bool topology = true) {
    bound = std::max(bound, c.bounds.error_bound);
    surplus = std::max(surplus, c.bounds.error_surplus);
    bounds.lo = std::min(bounds.lo, c.bounds.lo);
    bounds.hi = std::max(bounds.hi, c.bounds.hi);
    if (!topology) return;
    exact.hull({c.topology.exact_lo, c.topology.exact_hi});
    paper.hull({c.topology.paper_lo, c.topology.paper_hi});
    for (size_t w = 0; w < weight.size(); ++w) weight[w] = std::max(weight[w], c.topology.weight[w]);
  }
};

// Saturation's fold over the children of one vertex, four fields an instruction: the same bits as
// Saturation::add called child by child. The builds, in memory and banded, fold a few children
// into each of a volume's vertices, billions at the sizes a convert meets.
// Every field is a running max, in one of three vectors: the range and errors (-lo, hi,
// error_bound, error_surplus), the two intervals (-exact_lo, exact_hi, -paper_lo, paper_hi), the
// weights. A min is the max of the negated values (negation is exact), and each max keeps the
// operands in the order of the scalar comparison it replaces, so that of two equal values (0 and
// -0) the same one is kept. A child without an interval holds (+infinity, -infinity)
// (DiamondTopology), which enters the hull as -infinity in both of its lanes: every max passes
// over it, as hull() skips an empty interval. Every record a build writes holds its empty
// intervals so; the scalar Saturation::add takes any empty interval.
class ChildFold {
 public:
  explicit ChildFold(const DiamondBounds& range) {
#if defined(__SSE2__)
    bounds_ = _mm_setr_ps(-range.lo, range.hi, 0.0f, 0.0f);
    intervals_ = _mm_set1_ps(-std::numeric_limits<float>::infinity());
    weights_ = _mm_setzero_ps();
#else
    range_ = range;
#endif
  }

  // A child's record (Saturation::add): without `topology`, its range and errors only.
  void add(const Record& c, bool topology = true) {
#if defined(__SSE2__)
    // std::min(lo, c.lo) is c.lo < lo ? c.lo : lo, std::max(m, c.m) is m < c.m ? c.m : m: the
    // child's value first (MAXPS keeps its first operand only when it is greater).
    bounds_ = _mm_max_ps(_mm_xor_ps(_mm_loadu_ps(&c.bounds.lo), sign_mask(0x1)), bounds_);
    if (!topology) return;
    assert(in_hull_form(c.topology.exact_lo, c.topology.exact_hi) &&
           in_hull_form(c.topology.paper_lo, c.topology.paper_hi));
    // hull(): lo < o.lo ? lo : o.lo and hi > o.hi ? hi : o.hi, the running value first.
    // exact_lo, exact_hi, paper_lo, paper_hi
    intervals_ = _mm_max_ps(intervals_, _mm_xor_ps(_mm_loadu_ps(&c.topology.exact_lo), sign_mask(0x5)));
    // paper_hi, weight[0..2]: the first lane is not read.
    weights_ = _mm_max_ps(_mm_loadu_ps(&c.topology.paper_hi), weights_);
#else
    sat_.add(c, range_, topology);
#endif
  }

#if defined(__SSE2__)
  // finish_record of a vertex inside the data box that adds nothing to its children's topology
  // (without `topology`, or v not beyond both of its ends: no interval of its own, so no weight),
  // stored into `r`: the children's intervals and weights as they are, the range and errors
  // beside them. The same bits, from three stores and no round trip through a Saturation.
  void store_without_own_topology(const DiamondValues& dv, Record& r) const {
    const __m128 b = _mm_xor_ps(bounds_, sign_mask(0x1));  // lo, hi, the children's bound and surplus
    float error_bound, error_surplus;
    vertex_errors(dv, _mm_cvtss_f32(_mm_shuffle_ps(b, b, _MM_SHUFFLE(2, 2, 2, 2))),
                  _mm_cvtss_f32(_mm_shuffle_ps(b, b, _MM_SHUFFLE(3, 3, 3, 3))), error_bound, error_surplus);
    // The weights first: their first lane falls on paper_hi, which the intervals then write.
    _mm_storeu_ps(&r.topology.paper_hi, weights_);
    _mm_storeu_ps(&r.topology.exact_lo, _mm_xor_ps(intervals_, sign_mask(0x5)));
    _mm_storeu_ps(&r.bounds.lo, _mm_movelh_ps(b, _mm_unpacklo_ps(_mm_set_ss(error_bound), _mm_set_ss(error_surplus))));
  }
#endif

  // The saturation, and the vertex's range widened by its children's (its errors: theirs, the
  // saturation's bound and surplus, which finish_record adds the vertex's own to).
  Saturation finish(DiamondBounds& range) const {
#if defined(__SSE2__)
    // Stored as they lie in memory (static_asserts below), the weights first: their first lane
    // falls on paper_hi, which the intervals then write.
    Saturation s;
    _mm_storeu_ps(&s.paper.hi, weights_);
    // An interval no child entered is (+infinity, -infinity): empty, as hull() reads it.
    _mm_storeu_ps(&s.exact.lo, _mm_xor_ps(intervals_, sign_mask(0x5)));
    const __m128 b = _mm_xor_ps(bounds_, sign_mask(0x1));  // lo, hi, error_bound, error_surplus
    _mm_storeu_ps(&range.lo, b);
    s.bound = range.error_bound;
    s.surplus = range.error_surplus;
    return s;
#else
    range = range_;
    return sat_;
#endif
  }

 private:
#if defined(__SSE2__)
  // The loads above read four consecutive floats of a record from each of these.
  static_assert(offsetof(DiamondBounds, error_surplus) == 3 * sizeof(float));
  static_assert(offsetof(DiamondTopology, paper_hi) == offsetof(DiamondTopology, exact_lo) + 3 * sizeof(float));
  static_assert(offsetof(DiamondTopology, weight) == offsetof(DiamondTopology, paper_hi) + sizeof(float));
  static_assert(offsetof(Saturation, paper) == offsetof(Saturation, exact) + 2 * sizeof(float) &&
                offsetof(Saturation, weight) == offsetof(Saturation, paper) + 2 * sizeof(float));
  // An interval, or none as a record holds it: what add() may fold.
  static bool in_hull_form(float lo, float hi) {
    return lo < hi || (lo == DiamondTopology::kNone && hi == -DiamondTopology::kNone);
  }
  // The sign bit in the lanes of `lanes` (bit i: lane i).
  static __m128 sign_mask(int lanes) {
    const auto bit = [&](int i) { return (lanes >> i & 1) ? -0.0f : 0.0f; };
    return _mm_setr_ps(bit(0), bit(1), bit(2), bit(3));
  }
  __m128 bounds_, intervals_, weights_;
#else
  DiamondBounds range_;
  Saturation sat_;
#endif
};

// Where v's polyhedron lies, relative to v, in lattice steps: what the gradient and size weights
// need beyond the values. The same for every vertex of one diamond shape and scale.
struct DiamondShape {
  std::array<std::array<int64_t, 3>, 10> offset{};  // a, b, then the ring in cycle order
  int ring_count = 0;
  uint32_t real_ring = 0;  // bit i: ring vertex i is a lattice node (not mirrored)
  double child_tets = 0;   // full-resolution tetrahedra in one child tetrahedron of the diamond
};

inline DiamondShape shape_of(const Diamond& d, const Lattice& lattice) {
  DiamondShape s;
  auto rel = [&](const Coord& p) { return std::array<int64_t, 3>{p[0] - d.v[0], p[1] - d.v[1], p[2] - d.v[2]}; };
  s.offset[0] = rel(d.a);
  s.offset[1] = rel(d.b);
  s.ring_count = d.ring_count;
  for (int i = 0; i < d.ring_count; ++i) {
    s.offset[static_cast<size_t>(2 + i)] = rel(d.ring[i]);
    if (lattice.contains(d.ring[i])) s.real_ring |= 1u << i;
  }
  // Each level halves a tetrahedron; the finest (level 3k) are the 6 per unit cell.
  s.child_tets = std::ldexp(1.0, lattice.max_level() - (d.level + 1));
  return s;
}

// The shape finish_record needs: only the weights of a vertex with an interval of its own read it
// (with topology and weights, inside the data box, v beyond both ends), and it is not made for others.
inline DiamondShape shape_for_weights(const Diamond& d, const Lattice& lattice, const DiamondValues& dv,
                                      bool inside_box, bool topology, bool weights = true) {
  return topology && weights && inside_box && beyond_both_ends(dv) ? shape_of(d, lattice) : DiamondShape{};
}

// The gradient and size weights of a vertex whose exact interval x is not empty, over the
// tetrahedra (end, v, r_i, r_i+1) that refining v creates: the steepest linear gradient among them
// (value per lattice step), and how many full-resolution tetrahedra those that some isovalue in x
// cuts cover. A count of the coarse tetrahedra themselves would hardly vary (at most 16); their
// volume tells a feature the size of a voxel from one the size of the volume.
struct LocalWeights {
  double gradient = 0, size = 0;
};

// 1 / d where that is exact (d a power of two), else 0.
inline double exact_reciprocal(double d) {
  const auto bits = std::bit_cast<uint64_t>(d);
  const uint64_t exponent = bits >> 52 & 0x7ff;
  if ((bits & ((uint64_t{1} << 52) - 1)) != 0 || exponent == 0 || exponent >= 2046) return 0;
  return std::bit_cast<double>((bits & (uint64_t{1} << 63)) | (2046 - exponent) << 52);
}

// The tetrahedra (end, v, r_i, r_i+1) of a shape as local_weights walks them: the matrix M of their
// edges from v (rows: end, r_i, r_i+1) and its determinant, 0 where the tetrahedron is missing
// or degenerate. Where every det is a power of two and the offsets are at most 2^12 lattice
// steps (every scale up to 12), M's inverse is exact too, and for integer values up to 2^24 both
// Cramer's quotients and the inverse's sums are exact: the same gradient bit for bit, from a
// third of the work. Made once a process per class of diamonds (a band tile's templates point to
// it); left uninitialized until gradients_of fills it.
struct ShapeGradients {
  bool inverse;       // inv holds the exact inverse for every tetrahedron (above)
  double det[16];     // of tetrahedron t = e * ring_count + i
  double inv[9][16];  // M^-1 transposed: g_c = sum over rows of (f(row) - f(v)) * inv[row * 3 + c][t],
                      // tetrahedra side by side (local_weights takes two at a time)
};

// The determinant of a row-major 3x3 matrix, by the first row's cofactors.
inline double det3(const double m[9]) {
  return m[0] * (m[4] * m[8] - m[5] * m[7]) - m[1] * (m[3] * m[8] - m[5] * m[6]) + m[2] * (m[3] * m[7] - m[4] * m[6]);
}

// Tetrahedron (e, i)'s matrix M, row-major.
inline void edge_matrix(const DiamondShape& s, int e, int i, double m[9]) {
  const auto& pe = s.offset[static_cast<size_t>(e)];
  const auto& p1 = s.offset[static_cast<size_t>(2 + i)];
  const auto& p2 = s.offset[static_cast<size_t>(2 + (i + 1) % s.ring_count)];
  for (size_t c = 0; c < 3; ++c) {
    m[c] = double(pe[c]);
    m[3 + c] = double(p1[c]);
    m[6 + c] = double(p2[c]);
  }
}

inline ShapeGradients gradients_of(const DiamondShape& s) {
  ShapeGradients g;
  g.inverse = true;
  for (int e = 0; e < 2; ++e)
    for (int i = 0; i < s.ring_count; ++i) {
      const int t = e * s.ring_count + i, i1 = (i + 1) % s.ring_count;
      g.det[t] = 0;
      for (auto& entry : g.inv) entry[t] = 0;  // read, and masked out, beside a live tetrahedron
      if ((s.real_ring >> i & 1u) == 0 || (s.real_ring >> i1 & 1u) == 0) continue;
      double m[9];
      edge_matrix(s, e, i, m);
      for (double x : m) g.inverse = g.inverse && std::fabs(x) <= 4096;
      g.det[t] = det3(m);
      if (g.det[t] == 0) continue;
      const double r = exact_reciprocal(g.det[t]);
      g.inverse = g.inverse && r != 0;
      // inv[row][c] = cofactor(row, c) / det
      for (int row = 0; row < 3; ++row)
        for (int c = 0; c < 3; ++c) {
          const int r1 = (row + 1) % 3, r2 = (row + 2) % 3, c1 = (c + 1) % 3, c2 = (c + 2) % 3;
          g.inv[row * 3 + c][t] = (m[r1 * 3 + c1] * m[r2 * 3 + c2] - m[r1 * 3 + c2] * m[r2 * 3 + c1]) * r;
        }
    }
  return g;
}

// An integer of at most 2^24 in magnitude (every value of a 8- or 16-bit volume).
inline bool small_integer(float f) {
  return std::fabs(f) <= 16777216.0f && static_cast<float>(static_cast<int32_t>(f)) == f;
}

inline LocalWeights local_weights(const DiamondValues& dv, const DiamondShape& s, IsoInterval x,
                                  const ShapeGradients* gradients = nullptr) {
  if (!gradients) {
    const ShapeGradients own = gradients_of(s);
    return local_weights(dv, s, x, &own);
  }
  const ShapeGradients& g = *gradients;
  bool exact = g.inverse && small_integer(dv.fa) && small_integer(dv.fb) && small_integer(dv.fv);
  for (int i = 0; i < s.ring_count && exact; ++i) exact = small_integer(dv.ring[i]);
  LocalWeights w;
  // The steepest gradient's square: the root is monotone, so the root of the largest square is
  // the largest root, bit for bit, for one root where each tetrahedron took one.
  double steepest = 0;
#if defined(__SSE2__)
  if (exact && s.ring_count % 2 == 0) {
    // Two tetrahedra (i, i + 1) of an end at a time (rings have 4, 6 or 8 vertices), each in its
    // lane with the scalar loop's operations in its order, so the same bits; a missing or
    // degenerate tetrahedron's lane masked out.
    const int n = s.ring_count;
    const double fv = dv.fv;
    double f[9], d[9];  // ring values, and ring value - f(v); the first again after the last
    for (int i = 0; i < n; ++i) {
      f[i] = double(dv.ring[i]);
      d[i] = f[i] - fv;
    }
    f[n] = f[0];
    d[n] = d[0];
    const __m128d vv = _mm_set1_pd(fv), xlo = _mm_set1_pd(double(x.lo)), xhi = _mm_set1_pd(double(x.hi));
    __m128d top = _mm_setzero_pd(), cut_count = _mm_setzero_pd();
    for (int e = 0; e < 2; ++e) {
      const double fe = e == 0 ? dv.fa : dv.fb;
      const __m128d r0 = _mm_set1_pd(fe - fv), ve = _mm_set1_pd(fe);
      for (int i = 0; i < n; i += 2) {
        const int t = e * n + i;
        const __m128d live = _mm_cmpneq_pd(_mm_loadu_pd(g.det + t), _mm_setzero_pd());
        const __m128d r1 = _mm_loadu_pd(d + i), r2 = _mm_loadu_pd(d + i + 1);
        __m128d g2 = _mm_setzero_pd();
        for (int c = 0; c < 3; ++c) {
          const __m128d gc = _mm_add_pd(
              _mm_add_pd(_mm_mul_pd(r0, _mm_loadu_pd(g.inv[c] + t)), _mm_mul_pd(r1, _mm_loadu_pd(g.inv[3 + c] + t))),
              _mm_mul_pd(r2, _mm_loadu_pd(g.inv[6 + c] + t)));
          g2 = _mm_add_pd(g2, _mm_mul_pd(gc, gc));
        }
        top = _mm_max_pd(top, _mm_and_pd(g2, live));
        // Cut by some t in [x.lo, x.hi): some corner > t and some corner <= t.
        const __m128d f1 = _mm_loadu_pd(f + i), f2 = _mm_loadu_pd(f + i + 1);
        const __m128d lo = _mm_min_pd(_mm_min_pd(ve, vv), _mm_min_pd(f1, f2));
        const __m128d hi = _mm_max_pd(_mm_max_pd(ve, vv), _mm_max_pd(f1, f2));
        const __m128d cut = _mm_and_pd(_mm_cmplt_pd(_mm_max_pd(lo, xlo), _mm_min_pd(hi, xhi)), live);
        cut_count = _mm_add_pd(cut_count, _mm_and_pd(cut, _mm_set1_pd(1.0)));
      }
    }
    steepest = std::max(_mm_cvtsd_f64(top), _mm_cvtsd_f64(_mm_unpackhi_pd(top, top)));
    w.size = (_mm_cvtsd_f64(cut_count) + _mm_cvtsd_f64(_mm_unpackhi_pd(cut_count, cut_count))) * s.child_tets;
    w.gradient = std::sqrt(steepest);
    return w;
  }
#endif
  for (int e = 0; e < 2; ++e) {
    const double fe = e == 0 ? dv.fa : dv.fb;
    for (int i = 0; i < s.ring_count; ++i) {
      const int t = e * s.ring_count + i, i1 = (i + 1) % s.ring_count;
      if (g.det[t] == 0) continue;  // missing (a cut diamond) or degenerate: not a tetrahedron of a proper ring
      const double f1 = dv.ring[i], f2 = dv.ring[i1], fv = dv.fv;
      // Gradient g of the linear interpolant: (p - v) . g = f(p) - f(v) at p = end, r_i, r_i+1.
      const double r[3] = {fe - fv, f1 - fv, f2 - fv};
      double g2 = 0;
      if (exact) {
        for (int c = 0; c < 3; ++c) {
          const double gc = r[0] * g.inv[c][t] + r[1] * g.inv[3 + c][t] + r[2] * g.inv[6 + c][t];
          g2 += gc * gc;
        }
      } else {
        // Cramer's rule, each quotient correctly rounded.
        double m[9];
        edge_matrix(s, e, i, m);
        const double reciprocal = exact_reciprocal(g.det[t]);
        for (int c = 0; c < 3; ++c) {
          double mc[9];
          for (int k = 0; k < 9; ++k) mc[k] = k % 3 == c ? r[k / 3] : m[k];
          const double minor = det3(mc);
          // A product by an exact reciprocal is the quotient's bits for a third of a division's time.
          const double gc = reciprocal != 0 ? minor * reciprocal : minor / g.det[t];
          g2 += gc * gc;
        }
      }
      steepest = std::max(steepest, g2);
      // Cut by some t in [x.lo, x.hi): some corner > t and some corner <= t.
      const double lo = std::min({fe, fv, f1, f2}), hi = std::max({fe, fv, f1, f2});
      if (std::max(lo, double(x.lo)) < std::min(hi, double(x.hi))) w.size += s.child_tets;
    }
  }
  w.gradient = std::sqrt(steepest);
  return w;
}

// The record from what was gathered: the polyhedron's values, shape and range, whether every real
// polyhedron vertex lies in the data box, and the children's saturation. Without `topology`, the
// range and errors alone (the topology left empty), the same bits as with it. Without `weights`,
// the topology without its simplification weights (0), the rest the same bits as with them: a
// store's band 0 computed for an extraction that reads no weights (docs/FORMAT.md, "Band 0's
// records"), where the weights' gradients and sizes were a tenth of the CPU time of embryo's
// first `preserve` extraction at eps 120 (profiled), and a build for a store or a hierarchy that
// keeps none (BandedBuildOptions::weights).
inline Record finish_record(const DiamondValues& dv, const DiamondShape& shape, bool inside_box,
                            const DiamondBounds& range, Saturation sat, CriticalCounts& counts, bool topology = true,
                            const ShapeGradients* gradients = nullptr, bool weights = true) {
  Record r;
  r.bounds = range;
  // A diamond reaching past the data box is judged on the clamped field like any other: inside the
  // box that field is the data, and the traversal clips what it emits there to the box
  // (docs/METHOD.md, "Volumes that are not (2^k+1)^3").
  vertex_errors(dv, sat.bound, sat.surplus, r.bounds.error_bound, r.bounds.error_surplus);
  if (!topology) return r;
  if (!inside_box) {
    // The clipped surface's topology is not what the clamped field's rules see: the topology
    // modes refine such a diamond whatever the isovalue. It adds no weight of its own, so that
    // simplify mode with a delta above every feature's weight is mode none here too.
    constexpr float kInf = std::numeric_limits<float>::infinity();
    sat.exact.hull({-kInf, kInf});
    sat.paper.hull({-kInf, kInf});
  } else {
    // Unless v lies strictly beyond both a and b, neither rule flags an isovalue (docs/METHOD.md,
    // "The exact rule"): where one of a and b lies above v and the other not, the paper's rule asks
    // for equal signs at a and b too; where v ties the greater of two ends not above it, the
    // paper's pattern may be critical but its interval [max(fa, fb), fv) is empty. Most vertices
    // of smooth data, and of quantized data's plateaus, settled here without a call.
    IsoInterval exact, paper;
    if (beyond_both_ends(dv)) {
      exact = exact_interval(dv);
      paper = paper_interval(dv);
    }
    counts[0][static_cast<int>(dv.type)] += paper.empty() ? 0 : 1;
    counts[1][static_cast<int>(dv.type)] += exact.empty() ? 0 : 1;
    sat.exact.hull(exact);
    sat.paper.hull(paper);
    if (!exact.empty() && weights) {
      const LocalWeights w = local_weights(dv, shape, exact, gradients);
      sat.weight[0] = std::max(sat.weight[0], exact.length());
      sat.weight[1] = std::max(sat.weight[1], round_up(exact.length() * w.gradient));
      sat.weight[2] = std::max(sat.weight[2], round_up(w.size));
    }
  }
  if (!sat.exact.empty()) {
    r.topology.exact_lo = sat.exact.lo;
    r.topology.exact_hi = sat.exact.hi;
  }
  if (!sat.paper.empty()) {
    r.topology.paper_lo = sat.paper.lo;
    r.topology.paper_hi = sat.paper.hi;
  }
  r.topology.weight = weights ? sat.weight : std::array<float, 3>{0, 0, 0};
  return r;
}

// Whether the midpoint of `end` (d.a or d.b) and ring vertex i is a child of v's diamond d, but
// for that vertex's lying in the lattice. The children of tetrahedron (a, b, p, q) are (a, v, p,
// q) and (b, v, p, q), bisected at the midpoint of `end` and the farther of p and q (checked by
// the hierarchy test). Far vertices alternate around the ring, so each child is shared by two
// tetrahedra: each (end, far ring vertex) pair once. Leaves have no children.
inline bool is_child_pair(const Diamond& d, const Lattice& lattice, const Coord& end, int i) {
  if (d.level + 1 >= lattice.max_level()) return false;
  auto squared_distance = [](const Coord& p, const Coord& q) {
    int64_t s = 0;
    for (int a = 0; a < 3; ++a) s += (p[a] - q[a]) * (p[a] - q[a]);
    return s;
  };
  return squared_distance(end, d.ring[i]) >= squared_distance(end, d.ring[(i + 1) % d.ring_count]);
}

inline Coord midpoint(const Coord& p, const Coord& q) {
  return {(p[0] + q[0]) / 2, (p[1] + q[1]) / 2, (p[2] + q[2]) / 2};
}

// Calls f(u) for the refinement vertex u of each child tetrahedron of v's diamond d. A real far
// vertex always has a real tetrahedron.
template <class F>
void for_each_child(const Diamond& d, const Lattice& lattice, F f) {
  for (const Coord* end : {&d.a, &d.b})
    for (int i = 0; i < d.ring_count; ++i) {
      if (!is_child_pair(d, lattice, *end, i)) continue;
      if (!lattice.contains(d.ring[i])) continue;  // a missing tetrahedron of a cut diamond
      f(midpoint(*end, d.ring[i]));
    }
}

// Values at v's polyhedron (mirrored across the domain faces where the diamond is cut, paper
// Sec. 4.3) and their range, from value(c) of a lattice node (clamped into the data box beyond it);
// true when every real vertex lies in the data box.
template <class Value>
bool read_polyhedron(const Diamond& d, const Lattice& lattice, const std::array<int64_t, 3>& dims, Value value,
                     DiamondValues& dv, DiamondBounds& bounds) {
  auto in_box = [&](const Coord& c) { return c[0] < dims[0] && c[1] < dims[1] && c[2] < dims[2]; };
  dv.type = d.type;
  dv.fa = value(d.a);
  dv.fb = value(d.b);
  dv.fv = value(d.v);
  bool inside_box = in_box(d.a) && in_box(d.b);
  bounds.lo = std::min({dv.fa, dv.fb, dv.fv});
  bounds.hi = std::max({dv.fa, dv.fb, dv.fv});
  for (int i = 0; i < d.ring_count; ++i) {
    const bool real = lattice.contains(d.ring[i]);
    dv.ring[i] = value(real ? d.ring[i] : mirror_into(d.ring[i], lattice));
    if (!real) continue;
    inside_box = inside_box && in_box(d.ring[i]);
    bounds.lo = std::min(bounds.lo, dv.ring[i]);
    bounds.hi = std::max(bounds.hi, dv.ring[i]);
  }
  return inside_box;
}

// A vertex's diamond and the children for_each_child would call back, from the vertex's class:
// diamond_of depends on a scale-j vertex only through its coordinates mod 4 * 2^j (which of them
// are odd multiples of 2^j, and of those which lie 2^j above a multiple of 4 * 2^j), so one
// diamond per class, moved to the vertex, is diamond_of's, and the children for_each_child
// chooses by their distances are the class's too; only whether a ring vertex lies in the lattice
// is the vertex's own. The two were 6% of the instructions of embryo's convert (256^3), for the
// vertices at the faces of the data box (the others take band tiles' templates), and run for
// every vertex of the in-memory build.
class DiamondClasses {
 public:
  // The classes of scale `scale`, or of every scale (-1).
  DiamondClasses(const Lattice& lattice, int scale) : lattice_(lattice), first_(std::max(scale, 0)) {
    const int last = scale < 0 ? lattice.k - 1 : std::min(scale, lattice.k - 1);
    classes_.resize(static_cast<size_t>(std::max(0, last - first_ + 1)) * 64);
    for (int j = first_; j <= last; ++j)
      for (int key = 0; key < 64; ++key) {
        const Coord v{int64_t{key & 3} << j, int64_t{key >> 2 & 3} << j, int64_t{key >> 4} << j};
        if (((key & 1) | (key >> 2 & 1) | (key >> 4 & 1)) == 0) continue;  // of a coarser scale
        Class& c = classes_[static_cast<size_t>((j - first_) * 64 + key)];
        c.diamond = diamond_of(v, lattice);
        for (const int end : {0, 1})
          for (int i = 0; i < c.diamond.ring_count; ++i)
            if (is_child_pair(c.diamond, lattice, end == 0 ? c.diamond.a : c.diamond.b, i)) {
              c.end[c.children] = static_cast<uint8_t>(end);
              c.ring[c.children++] = static_cast<uint8_t>(i);
            }
        auto relative = [&](Coord& p) {
          for (int a = 0; a < 3; ++a) p[a] -= v[a];
        };
        relative(c.diamond.a);
        relative(c.diamond.b);
        for (int i = 0; i < c.diamond.ring_count; ++i) relative(c.diamond.ring[i]);
      }
  }

  // diamond_of(v) for a vertex v of a scale held.
  Diamond diamond(const Coord& v, int j) const {
    const Class& c = class_of(v, j);
    Diamond d = c.diamond;
    d.v = v;
    for (int a = 0; a < 3; ++a) {
      d.a[a] += v[a];
      d.b[a] += v[a];
    }
    for (int i = 0; i < d.ring_count; ++i)
      for (int a = 0; a < 3; ++a) d.ring[i][a] += v[a];
    return d;
  }
  // for_each_child(d, lattice, f), d the diamond() of v: the same children in the same order.
  template <class F>
  void for_each_child(const Diamond& d, int j, F f) const {
    const Class& c = class_of(d.v, j);
    for (int i = 0; i < c.children; ++i) {
      const Coord& end = c.end[i] ? d.b : d.a;
      const Coord& r = d.ring[c.ring[i]];
      if (!lattice_.contains(r)) continue;
      f(midpoint(end, r));
    }
  }

 private:
  struct Class {
    Diamond diamond;  // a, b and the ring relative to the vertex
    int children = 0;
    uint8_t end[16] = {}, ring[16] = {};  // child i: the midpoint of end (a or b) and ring vertex
  };
  const Class& class_of(const Coord& v, int j) const {
    assert(j >= first_ && (j - first_) * 64 < static_cast<int>(classes_.size()));
    const int key = static_cast<int>((v[0] >> j & 3) | (v[1] >> j & 3) << 2 | (v[2] >> j & 3) << 4);
    return classes_[static_cast<size_t>((j - first_) * 64 + key)];
  }
  const Lattice& lattice_;
  int first_;
  std::vector<Class> classes_;
};

template <class Grid>
class RecordBuilder {
 public:
  // `scale`: the only scale whose vertices build() is given, or -1 for any.
  explicit RecordBuilder(Grid& grid, int scale = -1)
      : grid_(grid), lattice_(grid.lattice()), classes_(grid.lattice(), scale) {}

  // Without `topology`, the range and errors alone; without `weights`, no simplification weights
  // (BandTile::build).
  void build(const Coord& v, CriticalCounts& counts, bool topology = true, bool weights = true) const {
    const int j = scale_of(v, lattice_);
    const Diamond d = classes_.diamond(v, j);
#ifndef NDEBUG
    {
      const Diamond e = diamond_of(v, lattice_);
      assert(d.type == e.type && d.level == e.level && d.ring_count == e.ring_count && d.a == e.a && d.b == e.b &&
             d.ring == e.ring);
      std::vector<Coord> by_class, by_distance;
      classes_.for_each_child(d, j, [&](const Coord& u) { by_class.push_back(u); });
      isotope::for_each_child(e, lattice_, [&](const Coord& u) { by_distance.push_back(u); });
      assert(by_class == by_distance);
    }
#endif
    DiamondValues dv;
    DiamondBounds range;
    const bool inside_box = read_polyhedron(
        d, lattice_, grid_.data_dims(), [&](const Coord& c) { return grid_.value(c); }, dv, range);
    ChildFold fold(range);
    classes_.for_each_child(d, j, [&](const Coord& u) {
      // Without a record, u's whole diamond lies beyond a face of the data box: no data node
      // below it, and what the traversal emits there is clipped away (clip_to_box).
      Record c;
      if (grid_.child(u, c)) fold.add(c, topology);
    });
    const Saturation sat = fold.finish(range);
    grid_.store(v, finish_record(dv, shape_for_weights(d, lattice_, dv, inside_box, topology, weights), inside_box,
                                 range, sat, counts, topology, nullptr, weights));
  }

 private:
  Grid& grid_;
  const Lattice& lattice_;
  DiamondClasses classes_;
};

}  // namespace isotope
