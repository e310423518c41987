#include "engine/extract.h"

#include <algorithm>
#include <cassert>
#include <chrono>
#include <cmath>
#include <stdexcept>
#include <vector>

#include "engine/kuhn.h"
#include "engine/marching_tetrahedra.h"
#include "engine/parallel.h"

namespace isotope {
namespace {

// A lattice node packed as x | y << 21 | z << 42: a tetrahedron is 32 bytes, and the midpoint
// of an edge is (p + q) >> 1, since each component of p + q is even and no carry crosses a field.
using Packed = uint64_t;
constexpr int kFieldBits = 21;
constexpr Packed kFieldMask = (Packed{1} << kFieldBits) - 1;
Packed pack(const Coord& c) {
  return static_cast<Packed>(c[0]) | static_cast<Packed>(c[1]) << kFieldBits | static_cast<Packed>(c[2]) << (2 * kFieldBits);
}
Coord unpack(Packed p) {
  return {static_cast<int64_t>(p & kFieldMask), static_cast<int64_t>((p >> kFieldBits) & kFieldMask),
          static_cast<int64_t>(p >> (2 * kFieldBits))};
}
using PackedTet = std::array<Packed, 4>;

int64_t orientation(const Tet& c) {
  const int64_t ax = c[1][0] - c[0][0], ay = c[1][1] - c[0][1], az = c[1][2] - c[0][2];
  const int64_t bx = c[2][0] - c[0][0], by = c[2][1] - c[0][1], bz = c[2][2] - c[0][2];
  const int64_t cx = c[3][0] - c[0][0], cy = c[3][1] - c[0][1], cz = c[3][2] - c[0][2];
  return ax * (by * cz - bz * cy) - ay * (bx * cz - bz * cx) + az * (bx * cy - by * cx);
}

// A piece of the traversal: a subtree to descend, or one tetrahedron to emit.
struct Piece {
  PackedTet tet{};
  int level = 0;
  bool positive = false;
  bool emit_only = false;
};

// Depth-first over the bisection tree (paper Sec. 3.2): cull by range, stop by the rule of
// design.md, emit at stopping tetrahedra and at the leaves.
class Traversal {
 public:
  Traversal(const MultiresVolume& mv, const ExtractOptions& options)
      : mv_(mv), lattice_(mv.lattice()), options_(options),
        builder_(options.iso, lattice_.side, mv.origin(), mv.spacing()) {
    for (int i = 0; i < 3; ++i) {
      box_max_[i] = mv.data_dims()[i] - 1;
      clip_ = clip_ || box_max_[i] < lattice_.n;
    }
  }

  // The traversal cut at `level` into pieces, in depth-first order: the subtrees rooted there and
  // the tetrahedra emitted above it. Running the pieces in this order is the whole traversal.
  std::vector<Piece> split(int level) {
    std::vector<Piece> pieces;
    pieces_ = &pieces;
    split_level_ = level;
    const int64_t n = lattice_.n;
    for (const Tet& root : kuhn_tetrahedra({0, 0, 0}, {n, n, n}))
      visit({pack(root[0]), pack(root[1]), pack(root[2]), pack(root[3])}, 0, orientation(root) > 0);
    pieces_ = nullptr;
    return pieces;
  }

  void run(const Piece& p) {
    if (p.emit_only) emit(p.tet, p.positive);
    else visit(p.tet, p.level, p.positive);
  }

  void keep_keys() { builder_.keep_keys(); }
  std::vector<uint64_t> take_keys() { return builder_.take_keys(); }
  Mesh take() { return builder_.take(); }
  const ExtractStats& stats() const { return stats_; }

 private:
  // `positive`: the corners in this order span a positively oriented tetrahedron. Bisection
  // keeps it for the first child and, at l mod 3 == 0, for the second; otherwise the second
  // child is mirrored (its corners are an odd permutation of the parent's, up to the midpoint).
  void visit(const PackedTet& t, int level, bool positive) {
    if (pieces_ && level == split_level_) return pieces_->push_back({t, level, positive, false});
    ++stats_.tets_visited;
    if (clip_ && outside_box(t)) return;
    if (level == lattice_.max_level()) return emit(t, positive);
    const Packed v = (t[0] + t[1]) >> 1;
    assert(mv_.has_record(unpack(v)) && "the outside test keeps the traversal near the data box");
    const int64_t slot = mv_.record_slot(unpack(v));
    const DiamondBounds& b = mv_.bounds(slot);
    if (!(b.lo <= options_.iso && options_.iso < b.hi)) return;  // no value on each side
    if (stops(b, slot)) return emit(t, positive);
    if (level % 3 == 0) {
      visit({t[0], t[2], t[3], v}, level + 1, positive);
      visit({t[1], t[3], t[2], v}, level + 1, positive);
    } else {
      visit({t[0], t[2], t[3], v}, level + 1, positive);
      visit({t[1], t[2], t[3], v}, level + 1, !positive);
    }
  }

  bool stops(const DiamondBounds& b, int64_t slot) const {
    const float err = options_.error == ErrorIndicator::bound ? b.error_bound : b.error_surplus;
    if (!(static_cast<double>(err) < options_.eps)) return false;
    const float iso = options_.iso;
    const DiamondTopology& rec = mv_.topology(slot);
    switch (options_.topology) {
      case TopologyMode::none: return true;
      case TopologyMode::paper: return !(rec.paper_lo <= iso && iso < rec.paper_hi);
      case TopologyMode::preserve:
        return !(rec.exact_lo <= iso && iso < rec.exact_hi && static_cast<double>(rec.weight) >= options_.delta);
    }
    return true;
  }

  // The tetrahedron lies in a half-space beyond a face of the data box: it meets the box in a
  // face at most. Leaves are unit-cell Kuhn tetrahedra, wholly inside or caught here.
  bool outside_box(const PackedTet& t) const {
    for (int a = 0; a < 3; ++a) {
      const int shift = a * kFieldBits;
      Packed lo = kFieldMask;
      for (Packed p : t) lo = std::min(lo, (p >> shift) & kFieldMask);
      if (static_cast<int64_t>(lo) >= box_max_[a]) return true;
    }
    return false;
  }

  void emit(const PackedTet& t, bool positive) {
    if (pieces_) return pieces_->push_back({t, 0, positive, true});
    ++stats_.tets_emitted;
    const Tet c{unpack(t[0]), unpack(t[1]), unpack(t[2]), unpack(t[3])};
    builder_.add_tet(c, {mv_.value(c[0]), mv_.value(c[1]), mv_.value(c[2]), mv_.value(c[3])}, positive);
  }

  const MultiresVolume& mv_;
  const Lattice& lattice_;
  ExtractOptions options_;
  MeshBuilder builder_;
  Coord box_max_{};
  bool clip_ = false;  // the data box is smaller than the lattice
  ExtractStats stats_;
  std::vector<Piece>* pieces_ = nullptr;  // while splitting
  int split_level_ = 0;
};

// What one piece produced: its own welded mesh and the edge key of each of its vertices.
struct PartMesh {
  Mesh mesh;
  std::vector<uint64_t> keys;
  ExtractStats stats;
};

// Welds the pieces' meshes in piece order. A vertex takes the next index the first time its
// edge appears, exactly as in one depth-first pass, so the result is the same, bit for bit,
// whatever the number of threads that built the pieces.
Mesh weld(std::vector<PartMesh>& parts, ExtractStats& stats) {
  size_t vertices = 0, triangles = 0;
  for (const PartMesh& p : parts) vertices += p.mesh.positions.size(), triangles += p.mesh.triangles.size();
  Mesh out;
  out.positions.reserve(vertices);
  out.triangles.reserve(triangles);
  EdgeVertexMap map(vertices);
  std::vector<uint32_t> remap;
  for (PartMesh& p : parts) {
    remap.resize(p.keys.size());
    for (size_t i = 0; i < p.keys.size(); ++i) {
      const auto fresh = static_cast<uint32_t>(out.positions.size());
      const uint32_t found = map.find_or_insert(p.keys[i], fresh);
      remap[i] = found == EdgeVertexMap::kAbsent ? fresh : found;
      if (found == EdgeVertexMap::kAbsent) out.positions.push_back(p.mesh.positions[i]);
    }
    for (const auto& t : p.mesh.triangles) out.triangles.push_back({remap[t[0]], remap[t[1]], remap[t[2]]});
    stats.tets_visited += p.stats.tets_visited;
    stats.tets_emitted += p.stats.tets_emitted;
    p = PartMesh{};  // free as we go
  }
  return out;
}

// Deep enough for a few hundred pieces (6 roots, two children per level), shallow enough that
// each is worth a task. Fixed, so the pieces do not depend on the thread count.
constexpr int kSplitLevel = 6;

void validate(const ExtractOptions& o) {
  if (!std::isfinite(o.iso)) throw std::invalid_argument("the isovalue must be a finite number");
  if (!(o.eps >= 0)) throw std::invalid_argument("eps must be >= 0");
  if (!(o.delta >= 0)) throw std::invalid_argument("delta must be >= 0");
}

}  // namespace

Mesh extract(const MultiresVolume& mv, const ExtractOptions& options, ExtractStats* stats) {
  const auto start = std::chrono::steady_clock::now();
  validate(options);
  ExtractOptions in_codes = options;  // identity unless the volume holds quantized codes
  if (mv.value_offset() != 0 || mv.value_scale() != 1) {
    in_codes.iso = static_cast<float>((static_cast<double>(options.iso) - mv.value_offset()) / mv.value_scale());
    in_codes.eps = options.eps / mv.value_scale();
    in_codes.delta = options.delta / mv.value_scale();
  }
  // Cut into pieces, traverse them in parallel, weld in order.
  Traversal top(mv, in_codes);
  const std::vector<Piece> pieces = top.split(std::min(kSplitLevel, mv.lattice().max_level()));
  std::vector<PartMesh> parts(pieces.size());
  parallel_for(int64_t{0}, static_cast<int64_t>(pieces.size()), [&](int64_t i) {
    Traversal t(mv, in_codes);
    t.keep_keys();
    t.run(pieces[static_cast<size_t>(i)]);
    PartMesh& part = parts[static_cast<size_t>(i)];
    part.stats = t.stats();
    part.keys = t.take_keys();
    part.mesh = t.take();
  });
  ExtractStats total = top.stats();
  Mesh mesh = weld(parts, total);
  if (stats) {
    *stats = total;
    stats->seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }
  return mesh;
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
