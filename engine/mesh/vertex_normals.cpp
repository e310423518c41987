#include "engine/mesh/vertex_normals.h"

#include <algorithm>
#include <cmath>
#include <memory>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "engine/core/huge_blocks.h"
#include "engine/core/lending_pool.h"
#include "engine/core/parallel.h"
#include "engine/mesh/vertex_parts.h"
#include "isotope/error.h"
#include "isotope/mesh.h"

namespace isotope {
namespace {

// The normals' sums part by part, on all threads: FINISH(part, sums) gets each part's sums once
// they are all added, sums[i - part.begin] for its vertex i. The same bits on any number of
// threads: the vertices are split into parts (VertexParts), and each part walks its triangles in
// order and sums the normals of those that touch its vertices. A vertex's sum thus adds its
// triangles' normals in triangle order, as one walk does; a triangle that spans two parts is
// computed in both, the same way. A part reads only the chunks of triangles that can touch it:
// embryo's eps 0 mesh (2.5 M triangles) took 35-42 ms on two threads when every part read every
// triangle, and takes 25-29 ms so.
template <class Finish>
void sum_by_parts(const Mesh& mesh, const Finish& finish) {
  const VertexParts plan = plan_vertex_parts(mesh.positions.size(), mesh.triangles);
  parallel_for(int64_t{0}, static_cast<int64_t>(plan.parts.size()), [&](int64_t p) {
    const VertexPart part = plan.parts[static_cast<size_t>(p)];
    // A part's sums are megabytes (24 bytes a vertex): on huge pages, faulted in by one call before
    // the zero-fill, not a 4 KB page at a time by it (docs/METHOD.md, "Fresh memory").
    std::vector<std::array<double, 3>, detail::HugePageAllocator<std::array<double, 3>>> sum;
    detail::resize_prefaulted(sum, part.end - part.begin);
    plan.for_each_triangle(static_cast<size_t>(p), mesh.triangles, [&](const std::array<uint32_t, 3>& t) {
      if (!part.holds(t[0]) && !part.holds(t[1]) && !part.holds(t[2])) return;
      const auto& a = mesh.positions[t[0]];
      const auto& b = mesh.positions[t[1]];
      const auto& c = mesh.positions[t[2]];
      const double u[3] = {double(b[0]) - a[0], double(b[1]) - a[1], double(b[2]) - a[2]};
      const double v[3] = {double(c[0]) - a[0], double(c[1]) - a[1], double(c[2]) - a[2]};
      const double m[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]};
      for (const uint32_t i : t)
        if (part.holds(i))
          for (int k = 0; k < 3; ++k) sum[i - part.begin][k] += m[k];
    });
    finish(part, sum);
  });
}

std::array<float, 3> unit(const std::array<double, 3>& s, const std::array<float, 3>& none) {
  const double len = std::sqrt(s[0] * s[0] + s[1] * s[1] + s[2] * s[2]);
  if (!(len > 0)) return none;
  return {static_cast<float>(s[0] / len), static_cast<float>(s[1] / len), static_cast<float>(s[2] / len)};
}

}  // namespace

// Every vertex is written, the ones without a normal too: the array is not zero-filled first, on
// one thread (a GLB of embryo's eps 0 mesh waited for 15 MB of zeros between the march and the
// normals).
void vertex_normals_into(const Mesh& mesh, std::span<std::array<float, 3>> normals, const std::array<float, 3>& none) {
  const size_t n = mesh.positions.size();
  if (normals.size() != n)
    throw InvalidInput("vertex normals: an array of " + std::to_string(normals.size()) + " for " + std::to_string(n) +
                       " vertices");
  sum_by_parts(mesh, [&](const VertexPart& part, const auto& sum) {
    for (uint32_t i = part.begin; i < part.end; ++i) normals[i] = unit(sum[i - part.begin], none);
  });
}

void for_each_vertex_normals_run(const Mesh& mesh, const std::array<float, 3>& none, const NormalsRun& done) {
  // Not zero-filled: each run writes what it hands out first.
  using Run = std::unique_ptr<std::array<float, 3>[]>;
  LendingPool<Run> runs;
  sum_by_parts(mesh, [&](const VertexPart& part, const auto& sum) {
    std::unique_ptr<Run> run = runs.take(
        [] { return std::make_unique<Run>(std::make_unique_for_overwrite<std::array<float, 3>[]>(kNormalsPerRun)); });
    for (uint32_t first = part.begin; first < part.end;) {
      const auto count = static_cast<uint32_t>(std::min<size_t>(kNormalsPerRun, part.end - first));
      for (uint32_t k = 0; k < count; ++k) (*run)[k] = unit(sum[first + k - part.begin], none);
      done(first, std::span<const std::array<float, 3>>(run->get(), count));
      first += count;
    }
    runs.give(std::move(run));
  });
}

std::vector<std::array<float, 3>> vertex_normals(const Mesh& mesh) {
  std::vector<std::array<float, 3>> normals(mesh.positions.size());
  vertex_normals_into(mesh, normals, {0, 0, 0});
  return normals;
}

}  // namespace isotope
