// Per-component measures and the full-versus-adaptive comparison (measure_components, compare_components).
#include "engine/diagnostics/component_report.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <numeric>
#include <stdexcept>
#include <string>

#include "engine/core/huge_blocks.h"
#include "engine/core/mix_hash.h"
#include "engine/topology/filed_edges.h"
#include "isotope/error.h"

namespace isotope {
namespace {

using Vec = std::array<double, 3>;

Vec to_vec(const std::array<float, 3>& p) { return {p[0], p[1], p[2]}; }
Vec sub(const Vec& a, const Vec& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
Vec cross(const Vec& a, const Vec& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
double dot(const Vec& a, const Vec& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
double length(const Vec& a) { return std::sqrt(dot(a, a)); }

// Union-find with path halving, for the comparison's groups.
class DisjointSets {
 public:
  explicit DisjointSets(size_t n) : parent_(n) { std::iota(parent_.begin(), parent_.end(), 0u); }
  uint32_t find(uint32_t x) {
    while (parent_[x] != x) x = parent_[x] = parent_[parent_[x]];
    return x;
  }
  void unite(uint32_t a, uint32_t b) {
    a = find(a), b = find(b);
    if (a != b) parent_[a] = b;
  }

 private:
  std::vector<uint32_t> parent_;
};

void check_mesh(const Mesh& mesh) {
  if (mesh.positions.size() >= (size_t{1} << 31))
    throw InvalidInput("component report: the mesh has 2^31 or more vertices");
  for (const auto& t : mesh.triangles)
    for (const uint32_t v : t)
      if (v >= mesh.positions.size())
        throw InvalidInput("component report: triangle refers to vertex " + std::to_string(v) + " of " +
                           std::to_string(mesh.positions.size()));
}

// The component of each vertex, numbered in order of the component's lowest vertex (its root,
// so numbered before any other of its vertices); -1 for vertices no triangle uses.
template <class Offset>
std::vector<int32_t> provisional_labels(const FiledEdges<Offset>& e, int32_t& count) {
  // Faulted in by one call first: 4 bytes a vertex, megabytes whose pages the fill took one at a
  // time (docs/METHOD.md, "Fresh memory").
  std::vector<int32_t> label;
  detail::resize_prefaulted(label, e.used.size());
  count = 0;
  for (size_t v = 0; v < label.size(); ++v) label[v] = !e.used[v] ? -1 : e.root[v] == v ? count++ : label[e.root[v]];
  return label;
}

// Vertex count and bounding box per component.
void add_vertices(const Mesh& mesh, const std::vector<int32_t>& label, std::vector<ComponentStats>& s) {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  for (ComponentStats& c : s) c.bbox_min = {kInf, kInf, kInf}, c.bbox_max = {-kInf, -kInf, -kInf};
  for (size_t v = 0; v < label.size(); ++v) {
    if (label[v] < 0) continue;
    ComponentStats& c = s[static_cast<size_t>(label[v])];
    ++c.vertices;
    for (int a = 0; a < 3; ++a) {
      c.bbox_min[a] = std::min(c.bbox_min[a], double{mesh.positions[v][a]});
      c.bbox_max[a] = std::max(c.bbox_max[a], double{mesh.positions[v][a]});
    }
  }
}

// Triangle count and area per component; the signed volume of each, taken about the centre of
// its box so that a component far from the origin does not lose digits to cancellation.
std::vector<double> add_triangles(const Mesh& mesh, const std::vector<int32_t>& label, std::vector<ComponentStats>& s) {
  std::vector<double> signed_volume(s.size(), 0.0);
  for (const auto& t : mesh.triangles) {
    const auto c = static_cast<size_t>(label[t[0]]);
    Vec centre;
    for (int a = 0; a < 3; ++a) centre[a] = 0.5 * (s[c].bbox_min[a] + s[c].bbox_max[a]);
    const Vec p0 = sub(to_vec(mesh.positions[t[0]]), centre), p1 = sub(to_vec(mesh.positions[t[1]]), centre),
              p2 = sub(to_vec(mesh.positions[t[2]]), centre);
    ++s[c].triangles;
    s[c].area += 0.5 * length(cross(sub(p1, p0), sub(p2, p0)));
    signed_volume[c] += dot(p0, cross(p1, p2)) / 6.0;
  }
  return signed_volume;
}

// Distinct, boundary and non-manifold edges per component, from the edges filed under each vertex.
template <class Offset>
void add_edges(const FiledEdges<Offset>& e, const std::vector<int32_t>& label, std::vector<ComponentStats>& s) {
  for (size_t v = 0; v < label.size(); ++v) {
    if (label[v] < 0) continue;
    ComponentStats& c = s[static_cast<size_t>(label[v])];
    for_each_edge_of(e, v, [&](uint32_t, int64_t triangles) {
      ++c.edges;
      if (triangles == 1) ++c.boundary_edges;
      if (triangles > 2) ++c.nonmanifold_edges;
    });
  }
}

void finish(ComponentStats& c, double signed_volume) {
  c.euler_characteristic = c.vertices - c.edges + c.triangles;
  c.closed = c.boundary_edges == 0 && c.nonmanifold_edges == 0;
  if (!c.closed) return;
  const int64_t twice_genus = 2 - c.euler_characteristic;
  if (twice_genus >= 0 && twice_genus % 2 == 0) c.genus = twice_genus / 2;
  c.volume = std::fabs(signed_volume);
  c.encloses_inside = signed_volume > 0;
}

// ---- Comparison --------------------------------------------------------------------------------

constexpr double kShare = 0.1;                           // matching rule, step 3
constexpr double kMinLatticeBudget = 4.0 * 1024 * 1024;  // extra samples on long triangles, both meshes
constexpr size_t kMaxQueries = 200000;                   // samples per mesh that look for a neighbour
constexpr size_t kMinQueries = 64;                       // ... at least, per component

struct Cell {
  int32_t x = 0, y = 0, z = 0;
  bool operator==(const Cell&) const = default;
};

// Open-addressing map from the cells of the search grid to their index: millions of lookups,
// where std::unordered_map's node per entry would dominate.
class CellMap {
 public:
  static constexpr uint32_t kAbsent = std::numeric_limits<uint32_t>::max();

  explicit CellMap(size_t expected) {
    size_t capacity = 16;
    while (capacity < 2 * expected) capacity *= 2;
    slots_.resize(capacity);
  }
  // The value of `key`; when absent, inserts `value` and returns it.
  uint32_t find_or_insert(const Cell& key, uint32_t value) {
    if (2 * (size_ + 1) > slots_.size()) grow();
    Slot& s = slots_[probe(key)];
    if (s.value == kAbsent) s = {key, value}, ++size_;
    return s.value;
  }
  uint32_t find(const Cell& key) const { return slots_[probe(key)].value; }

 private:
  struct Slot {
    Cell key;
    uint32_t value = kAbsent;
  };
  // The slot holding key, or the empty slot where it would go.
  size_t probe(const Cell& k) const {
    const uint64_t xy = uint64_t{static_cast<uint32_t>(k.x)} | uint64_t{static_cast<uint32_t>(k.y)} << 32;
    const size_t mask = slots_.size() - 1;
    size_t i = static_cast<size_t>(mix64(xy ^ mix64(static_cast<uint32_t>(k.z)))) & mask;
    while (slots_[i].value != kAbsent && !(slots_[i].key == k)) i = (i + 1) & mask;
    return i;
  }
  void grow() {
    std::vector<Slot> old(slots_.size() * 2);
    old.swap(slots_);
    for (const Slot& s : old)
      if (s.value != kAbsent) slots_[probe(s.key)] = s;
  }

  std::vector<Slot> slots_;
  size_t size_ = 0;
};

// A uniform grid of cubic cells anchored at a corner shared by both meshes.
struct Grid {
  Vec origin{0, 0, 0};
  double size = 1;
  int32_t axis(const Vec& p, int a) const { return static_cast<int32_t>(std::floor((p[a] - origin[a]) / size)); }
  Cell cell(const Vec& p) const { return {axis(p, 0), axis(p, 1), axis(p, 2)}; }
  // The cell as one number, 21 bits per axis: for grids of at most 2^20 cells per axis over the
  // meshes' box (one more on each side for rounding).
  uint64_t packed(const Vec& p) const {
    const auto bits = [&](int a) { return static_cast<uint64_t>(axis(p, a) + 1) & 0x1fffff; };
    return bits(0) << 42 | bits(1) << 21 | bits(2);
  }
};

struct Sample {
  Vec p;
  int32_t component;
};

// Calls f(point) for the points of the barycentric lattice of spacing <= h on triangle t other
// than its corners; nothing when every edge is at most 2h long, since every point of such a
// triangle is within 2h / sqrt(3) of a corner, no farther than thinning may move a sample anyway
// (the diagonal of a thinning cell, for h = tolerance / 2).
template <class F>
void for_lattice_points(const Mesh& mesh, const std::array<uint32_t, 3>& t, double h, F f) {
  const Vec a = to_vec(mesh.positions[t[0]]), ab = sub(to_vec(mesh.positions[t[1]]), a),
            ac = sub(to_vec(mesh.positions[t[2]]), a);
  const double longest = std::max({length(ab), length(ac), length(sub(ac, ab))});
  if (longest <= 2 * h) return;
  const auto n = static_cast<int64_t>(std::ceil(longest / h));
  const double step = 1.0 / static_cast<double>(n);
  for (int64_t i = 0; i <= n; ++i)
    for (int64_t j = 0; i + j <= n; ++j) {
      if ((i == 0 && j == 0) || i == n || j == n) continue;
      const double u = static_cast<double>(i) * step, w = static_cast<double>(j) * step;
      f(Vec{a[0] + u * ab[0] + w * ac[0], a[1] + u * ab[1] + w * ac[1], a[2] + u * ab[2] + w * ac[2]});
    }
}

// How many lattice points for_lattice_points would make on the whole mesh (as a double: the
// count of a tiny spacing overflows 64 bits).
double lattice_points(const Mesh& mesh, double h) {
  double total = 0;
  for (const auto& t : mesh.triangles) {
    const Vec a = to_vec(mesh.positions[t[0]]), b = to_vec(mesh.positions[t[1]]), c = to_vec(mesh.positions[t[2]]);
    const double longest = std::max({length(sub(b, a)), length(sub(c, a)), length(sub(c, b))});
    if (longest <= 2 * h) continue;
    const double n = std::ceil(longest / h);
    total += (n + 1) * (n + 2) / 2 - 3;
  }
  return total;
}

// Matching rule, step 1: vertices then lattice points, the first of each (cell, component) in
// that order, found by sorting the offers' cell keys (no hash table to size for millions of
// offers of which a fraction are kept).
std::vector<Sample> surface_samples(const Mesh& mesh, const std::vector<int32_t>& label, const Grid& thin,
                                    double lattice) {
  std::vector<Sample> offers;
  offers.reserve(label.size() + static_cast<size_t>(lattice_points(mesh, lattice)));
  for (size_t v = 0; v < label.size(); ++v)
    if (label[v] >= 0) offers.push_back({to_vec(mesh.positions[v]), label[v]});
  for (const auto& t : mesh.triangles)
    for_lattice_points(mesh, t, lattice, [&](const Vec& p) { offers.push_back({p, label[t[0]]}); });
  struct Key {
    uint64_t cell;
    uint32_t component, offer;
    bool operator<(const Key& o) const {
      return cell != o.cell ? cell < o.cell : component != o.component ? component < o.component : offer < o.offer;
    }
  };
  std::vector<Key> keys(offers.size());
  for (size_t i = 0; i < offers.size(); ++i)
    keys[i] = {thin.packed(offers[i].p), static_cast<uint32_t>(offers[i].component), static_cast<uint32_t>(i)};
  std::sort(keys.begin(), keys.end());
  std::vector<uint8_t> kept(offers.size(), 0);
  size_t count = 0;
  for (size_t i = 0; i < keys.size(); ++i)
    if (i == 0 || keys[i].cell != keys[i - 1].cell || keys[i].component != keys[i - 1].component)
      kept[keys[i].offer] = 1, ++count;
  std::vector<Sample> samples;
  samples.reserve(count);
  for (size_t i = 0; i < offers.size(); ++i)
    if (kept[i]) samples.push_back(offers[i]);
  return samples;
}

// Samples bucketed by cells of the search grid (size = tolerance), in sample order within a cell.
class SampleGrid {
 public:
  SampleGrid(const std::vector<Sample>& samples, const Grid& grid)
      : samples_(samples), grid_(grid), cells_(samples.size() / 8) {
    std::vector<uint32_t> cell_of(samples.size());
    for (size_t i = 0; i < samples.size(); ++i) {
      const auto next = static_cast<uint32_t>(start_.size());
      cell_of[i] = cells_.find_or_insert(grid_.cell(samples[i].p), next);
      if (cell_of[i] == next) start_.push_back(0);
      ++start_[cell_of[i]];
    }
    std::exclusive_scan(start_.begin(), start_.end(), start_.begin(), 0u);
    start_.push_back(static_cast<uint32_t>(samples.size()));
    order_.resize(samples.size());
    std::vector<uint32_t> fill(start_.begin(), start_.end() - 1);
    for (size_t i = 0; i < samples.size(); ++i) order_[fill[cell_of[i]]++] = static_cast<uint32_t>(i);
  }

  // The component of the nearest sample within the cell size of p, or -1; ties go to the lower
  // sample index, so the answer does not depend on the order cells are visited in.
  int32_t nearest(const Vec& p) const {
    const Cell c = grid_.cell(p);
    double best = grid_.size * grid_.size;
    uint32_t found = CellMap::kAbsent;
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const uint32_t id = cells_.find({c.x + dx, c.y + dy, c.z + dz});
          if (id == CellMap::kAbsent) continue;
          for (uint32_t k = start_[id]; k < start_[id + 1]; ++k) {
            const uint32_t s = order_[k];
            const Vec d = sub(samples_[s].p, p);
            const double d2 = dot(d, d);
            if (d2 < best || (d2 == best && s < found)) best = d2, found = s;
          }
        }
    return found == CellMap::kAbsent ? -1 : samples_[found].component;
  }

 private:
  const std::vector<Sample>& samples_;
  Grid grid_;
  CellMap cells_;
  std::vector<uint32_t> start_, order_;
};

// The samples that look for a neighbour: all of them up to kMaxQueries, else an even hashed
// subset that keeps at least kMinQueries (or all) of every component and always its first.
std::vector<uint32_t> query_subset(const std::vector<Sample>& samples, size_t components) {
  std::vector<uint32_t> chosen;
  if (samples.size() <= kMaxQueries) {
    chosen.resize(samples.size());
    std::iota(chosen.begin(), chosen.end(), 0u);
    return chosen;
  }
  const size_t stride = (samples.size() + kMaxQueries - 1) / kMaxQueries;
  std::vector<size_t> per(components, 0), seen(components, 0);
  for (const Sample& s : samples) ++per[static_cast<size_t>(s.component)];
  for (size_t i = 0; i < samples.size(); ++i) {
    const auto c = static_cast<size_t>(samples[i].component);
    const size_t own = std::clamp<size_t>(per[c] / kMinQueries, 1, stride);
    if (seen[c]++ == 0 || mix64(i) % own == 0) chosen.push_back(static_cast<uint32_t>(i));
  }
  return chosen;
}

// Queries per component of one side, and the (full, adaptive) key of each hit.
struct Hits {
  std::vector<int64_t> queries;
  std::vector<uint64_t> pairs;
  int64_t matched = 0;
};

uint64_t pair_key(int32_t full, int32_t adaptive) {
  return uint64_t{static_cast<uint32_t>(full)} << 32 | static_cast<uint32_t>(adaptive);
}

// Matching rule, step 2, for the samples of one side against the grid of the other.
Hits look_up(const std::vector<Sample>& samples, size_t components, const SampleGrid& other, bool from_full) {
  Hits h;
  h.queries.assign(components, 0);
  for (const uint32_t i : query_subset(samples, components)) {
    const Sample& s = samples[i];
    ++h.queries[static_cast<size_t>(s.component)];
    const int32_t o = other.nearest(s.p);
    if (o < 0) continue;
    ++h.matched;
    h.pairs.push_back(from_full ? pair_key(s.component, o) : pair_key(o, s.component));
  }
  std::sort(h.pairs.begin(), h.pairs.end());
  return h;
}

bool clear_share(int64_t hits, int64_t queries) {
  return hits > 0 && static_cast<double>(hits) >= kShare * static_cast<double>(queries);
}

// Per (full << 32 | adaptive): hits from the full side's samples, and from the adaptive side's.
using PairHits = std::map<uint64_t, std::array<int64_t, 2>>;

PairHits count_pairs(const Hits& from_full, const Hits& from_adaptive) {
  PairHits count;
  for (const uint64_t k : from_full.pairs) ++count[k][0];
  for (const uint64_t k : from_adaptive.pairs) ++count[k][1];
  return count;
}

// Matching rule, step 3: the related (full, adaptive) pairs.
std::vector<std::pair<int32_t, int32_t>> related_pairs(const PairHits& count, const Hits& from_full,
                                                       const Hits& from_adaptive) {
  std::vector<std::pair<int32_t, int32_t>> related;
  for (const auto& [key, n] : count) {
    const auto f = static_cast<int32_t>(key >> 32), a = static_cast<int32_t>(key & 0xffffffffu);
    if (clear_share(n[0], from_full.queries[static_cast<size_t>(f)]) ||
        clear_share(n[1], from_adaptive.queries[static_cast<size_t>(a)]))
      related.push_back({f, a});
  }
  return related;
}

// How both meshes are sampled (matching rule, step 1) and searched (step 2).
struct Sampling {
  Grid search, thin;
  double lattice = 1;  // spacing of the lattice points on long triangles
};

// Grids anchored at the meshes' common corner: search cells of the tolerance, thinning cells of a
// third of it (at least 2^-20 of the extent, for Grid::packed), lattice points every half
// tolerance on triangles longer than the tolerance. A full-resolution mesh, whose triangles are
// about a voxel, then gets no lattice points at the tolerances this is meant for. The spacing
// is doubled while the points would outnumber the triangles of both meshes (or 4 M if more), so
// that a tolerance below the voxel spacing costs no more than another pass over the meshes.
Sampling make_sampling(const Mesh& full, const MeshComponents& fc, const Mesh& adaptive, const MeshComponents& ac,
                       double tolerance) {
  if (!std::isfinite(tolerance) || tolerance <= 0)
    throw InvalidInput("compare_components: tolerance must be finite and > 0, got " + std::to_string(tolerance));
  constexpr double kInf = std::numeric_limits<double>::infinity();
  Vec lo{kInf, kInf, kInf}, hi{-kInf, -kInf, -kInf};
  for (const auto* list : {&fc.components, &ac.components})
    for (const ComponentStats& c : *list)
      for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], c.bbox_min[a]), hi[a] = std::max(hi[a], c.bbox_max[a]);
  Sampling s{{lo, tolerance}, {lo, tolerance / 3}, tolerance / 2};
  if (!(lo[0] <= hi[0])) return s;  // both meshes empty
  const double extent = std::max({hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]});
  if (extent / tolerance >= 0x1.0p30)
    throw InvalidInput("compare_components: tolerance " + std::to_string(tolerance) +
                       " is too small for the meshes' extent " + std::to_string(extent));
  s.thin.size = std::max(s.thin.size, extent * 0x1.0p-20);  // Grid::packed
  const double budget =
      std::clamp(static_cast<double>(full.triangles.size() + adaptive.triangles.size()), kMinLatticeBudget, 0x1.0p30);
  while (lattice_points(full, s.lattice) + lattice_points(adaptive, s.lattice) > budget) s.lattice *= 2;
  return s;
}

// Matching rule, step 4, for one group; nothing when the topology is the same.
std::optional<ChangeKind> classify(const std::vector<int>& f, const std::vector<int>& a,
                                   const std::vector<ComponentStats>& fs, const std::vector<ComponentStats>& as) {
  if (a.empty()) return ChangeKind::lost;
  if (f.empty()) return ChangeKind::appeared;
  if (f.size() > 1 && a.size() > 1) return ChangeKind::rearranged;
  if (f.size() > 1) return ChangeKind::merged;
  if (a.size() > 1) return ChangeKind::split;
  const ComponentStats &x = fs[static_cast<size_t>(f[0])], &y = as[static_cast<size_t>(a[0])];
  if (x.genus && y.genus) {
    if (*y.genus < *x.genus) return ChangeKind::handles_closed;
    if (*y.genus > *x.genus) return ChangeKind::handles_opened;
    return std::nullopt;
  }
  if (x.closed == y.closed && x.euler_characteristic == y.euler_characteristic) return std::nullopt;
  return ChangeKind::euler_changed;
}

// Totals over a group's side: Euler characteristic, and genus when every component has one.
std::pair<int64_t, std::optional<int64_t>> totals(const std::vector<int>& ids, const std::vector<ComponentStats>& s) {
  int64_t chi = 0;
  std::optional<int64_t> genus = 0;
  for (const int i : ids) {
    const ComponentStats& c = s[static_cast<size_t>(i)];
    chi += c.euler_characteristic;
    genus = genus && c.genus ? std::optional<int64_t>(*genus + *c.genus) : std::nullopt;
  }
  return {chi, genus};
}

void add_group(ComponentComparison& r, std::vector<int> f, std::vector<int> a) {
  const std::optional<ChangeKind> kind = classify(f, a, r.full_components, r.adaptive_components);
  if (!kind) {
    r.matched_unchanged.push_back({f[0], a[0]});
    return;
  }
  const auto [chi_f, genus_f] = totals(f, r.full_components);
  const auto [chi_a, genus_a] = totals(a, r.adaptive_components);
  ComponentChange c{*kind, std::move(f), std::move(a), 0, chi_a - chi_f};
  if (genus_f && genus_a) c.genus_change = *genus_a - *genus_f;
  r.changes.push_back(std::move(c));
}

// Matching rule, step 4a: a many-to-many group with as many components on each side is taken as
// one-to-one pairs when every component has a clear favourite (the largest share of its own
// samples, at least twice the next) and that favourite picks it back. Small components close together (noise specks
// a voxel or two apart) otherwise form groups that the coarse mesh did not rearrange at all.
// A real rearrangement (a join moved from A-B to B-C) has a component whose best partner looks
// elsewhere, and stays one group.
std::optional<std::vector<int>> mutual_best(const std::vector<int>& f, const std::vector<int>& a, const PairHits& count,
                                            const Hits& from_full, const Hits& from_adaptive) {
  if (f.size() != a.size() || f.size() < 2) return std::nullopt;
  auto hits = [&](int fi, int ai, int side) {
    const auto it = count.find(static_cast<uint64_t>(fi) << 32 | static_cast<uint32_t>(ai));
    return it == count.end() ? int64_t{0} : it->second[static_cast<size_t>(side)];
  };
  auto best = [&](int self, const std::vector<int>& others, bool self_is_full) {
    const Hits& h = self_is_full ? from_full : from_adaptive;
    const double queries = static_cast<double>(std::max<int64_t>(1, h.queries[static_cast<size_t>(self)]));
    int pick = -1;
    double top = 0, second = 0;
    for (const int o : others) {
      const double share = static_cast<double>(self_is_full ? hits(self, o, 0) : hits(o, self, 1)) / queries;
      if (share > top)
        second = top, top = share, pick = o;
      else
        second = std::max(second, share);
    }
    return top >= 2 * second ? pick : -1;  // a clear favourite, or none
  };
  std::vector<int> partner;  // per position in f: the adaptive component
  for (const int fi : f) {
    const int ai = best(fi, a, true);
    if (ai < 0 || best(ai, f, false) != fi) return std::nullopt;
    partner.push_back(ai);
  }
  std::vector<int> sorted = partner;
  std::sort(sorted.begin(), sorted.end());
  if (std::adjacent_find(sorted.begin(), sorted.end()) != sorted.end()) return std::nullopt;
  return partner;
}

// Matching rule, step 4: the connected groups of the relation, by lowest full index, then the
// adaptive components related to nothing.
void classify_groups(ComponentComparison& r, const std::vector<std::pair<int32_t, int32_t>>& related,
                     const PairHits& count, const Hits& from_full, const Hits& from_adaptive) {
  const size_t nf = r.full_components.size(), na = r.adaptive_components.size();
  DisjointSets sets(nf + na);
  for (const auto& [f, a] : related) sets.unite(static_cast<uint32_t>(f), static_cast<uint32_t>(nf + a));
  std::vector<std::vector<int>> full_of(nf + na), adaptive_of(nf + na);
  for (size_t i = 0; i < nf + na; ++i) {
    const uint32_t root = sets.find(static_cast<uint32_t>(i));
    if (i < nf)
      full_of[root].push_back(static_cast<int>(i));
    else
      adaptive_of[root].push_back(static_cast<int>(i - nf));
  }
  std::vector<uint8_t> done(nf + na, 0);
  for (size_t i = 0; i < nf + na; ++i) {
    const uint32_t root = sets.find(static_cast<uint32_t>(i));
    if (done[root]) continue;
    done[root] = 1;
    if (const auto pairs = mutual_best(full_of[root], adaptive_of[root], count, from_full, from_adaptive)) {
      for (size_t k = 0; k < pairs->size(); ++k) add_group(r, {full_of[root][k]}, {(*pairs)[k]});
      continue;
    }
    add_group(r, std::move(full_of[root]), std::move(adaptive_of[root]));
  }
}

}  // namespace

MeshComponents label_components(const Mesh& mesh) {
  check_mesh(mesh);
  int32_t count = 0;
  std::vector<int32_t> label;
  std::vector<ComponentStats> stats;
  std::vector<double> signed_volume;
  with_filed_edges(mesh, [&](const auto& edges) {
    label = provisional_labels(edges, count);
    stats.resize(static_cast<size_t>(count));
    add_vertices(mesh, label, stats);
    signed_volume = add_triangles(mesh, label, stats);
    add_edges(edges, label, stats);
  });
  for (size_t c = 0; c < stats.size(); ++c) finish(stats[c], signed_volume[c]);
  // Provisional numbers follow the lowest vertex, so they are the final tie-break.
  std::vector<int32_t> order(stats.size());
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](int32_t a, int32_t b) {
    const ComponentStats &x = stats[static_cast<size_t>(a)], &y = stats[static_cast<size_t>(b)];
    if (x.triangles != y.triangles) return x.triangles > y.triangles;
    if (x.bbox_min != y.bbox_min) return x.bbox_min < y.bbox_min;
    return a < b;
  });
  MeshComponents out;
  out.components.reserve(stats.size());
  std::vector<int32_t> rank(stats.size());
  for (size_t i = 0; i < order.size(); ++i) {
    rank[static_cast<size_t>(order[i])] = static_cast<int32_t>(i);
    out.components.push_back(stats[static_cast<size_t>(order[i])]);
  }
  for (int32_t& l : label)
    if (l >= 0) l = rank[static_cast<size_t>(l)];
  out.vertex_component = std::move(label);
  return out;
}

std::vector<ComponentStats> measure_components(const Mesh& mesh) { return label_components(mesh).components; }

MeshTopology total_topology(const std::vector<ComponentStats>& components) {
  MeshTopology t;
  t.components = static_cast<int64_t>(components.size());
  for (const ComponentStats& c : components) {
    t.vertices += c.vertices;
    t.triangles += c.triangles;
    t.edges += c.edges;
    t.boundary_edges += c.boundary_edges;
    t.nonmanifold_edges += c.nonmanifold_edges;
  }
  t.euler_characteristic = t.vertices - t.edges + t.triangles;
  return t;
}

std::string_view to_string(ChangeKind kind) {
  switch (kind) {
    case ChangeKind::lost: return "lost";
    case ChangeKind::appeared: return "appeared";
    case ChangeKind::merged: return "merged";
    case ChangeKind::split: return "split";
    case ChangeKind::rearranged: return "rearranged";
    case ChangeKind::handles_closed: return "handles_closed";
    case ChangeKind::handles_opened: return "handles_opened";
    case ChangeKind::euler_changed: return "euler_changed";
  }
  return "unknown";
}

ComponentComparison compare_components(const Mesh& full, const Mesh& adaptive, double tolerance) {
  return compare_components(full, label_components(full), adaptive, label_components(adaptive), tolerance);
}

ComponentComparison compare_components(const Mesh& full, const MeshComponents& full_components, const Mesh& adaptive,
                                       const MeshComponents& adaptive_components, double tolerance) {
  if (full_components.vertex_component.size() != full.positions.size() ||
      adaptive_components.vertex_component.size() != adaptive.positions.size())
    throw InvalidInput("compare_components: the component labels are not those of the meshes");
  const Sampling sampling = make_sampling(full, full_components, adaptive, adaptive_components, tolerance);
  ComponentComparison r;
  r.full_components = full_components.components;
  r.adaptive_components = adaptive_components.components;
  const std::vector<Sample> fs =
      surface_samples(full, full_components.vertex_component, sampling.thin, sampling.lattice);
  const std::vector<Sample> as =
      surface_samples(adaptive, adaptive_components.vertex_component, sampling.thin, sampling.lattice);
  const SampleGrid full_grid(fs, sampling.search), adaptive_grid(as, sampling.search);
  const Hits from_full = look_up(fs, r.full_components.size(), adaptive_grid, true);
  const Hits from_adaptive = look_up(as, r.adaptive_components.size(), full_grid, false);
  r.full_samples = std::accumulate(from_full.queries.begin(), from_full.queries.end(), int64_t{0});
  r.adaptive_samples = std::accumulate(from_adaptive.queries.begin(), from_adaptive.queries.end(), int64_t{0});
  r.full_samples_matched = from_full.matched;
  r.adaptive_samples_matched = from_adaptive.matched;
  const PairHits count = count_pairs(from_full, from_adaptive);
  classify_groups(r, related_pairs(count, from_full, from_adaptive), count, from_full, from_adaptive);
  // Groups taken as pairs (step 4a) are added in group order; restore the documented order.
  std::sort(r.matched_unchanged.begin(), r.matched_unchanged.end());
  std::stable_sort(r.changes.begin(), r.changes.end(), [](const ComponentChange& x, const ComponentChange& y) {
    auto key = [](const ComponentChange& c) {
      return c.full.empty() ? std::pair{1, c.adaptive[0]} : std::pair{0, c.full[0]};
    };
    return key(x) < key(y);
  });
  return r;
}

}  // namespace isotope
