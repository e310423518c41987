#include "engine/mesh/vertex_parts.h"

#include "engine/core/parallel.h"

namespace isotope {

namespace {

constexpr int64_t kMostParts = 64;
constexpr int64_t kMostFullReadParts = 4;  // parts that each read all triangles, at most

}  // namespace

VertexParts plan_vertex_parts(size_t n, const Mesh::Array<std::array<uint32_t, 3>>& triangles) {
  VertexParts plan;
  const int64_t chunk_count = chunks_of(triangles.size());
  const auto equal_parts = [&](int64_t count) {
    plan.parts.resize(static_cast<size_t>(count));
    for (int64_t q = 0; q < count; ++q)
      plan.parts[static_cast<size_t>(q)] = {
          static_cast<uint32_t>(n * static_cast<size_t>(q) / static_cast<size_t>(count)),
          static_cast<uint32_t>(n * static_cast<size_t>(q + 1) / static_cast<size_t>(count))};
  };
  if (runs_serially(0, chunk_count) || n < 2) {
    equal_parts(1);
    return plan;
  }
  std::vector<std::array<uint32_t, 2>> range(static_cast<size_t>(chunk_count));  // lowest, highest vertex
  parallel_for(int64_t{0}, chunk_count, [&](int64_t k) {
    const auto [begin, end] = chunk_triangles(k, triangles.size());
    uint32_t lo = UINT32_MAX, hi = 0;
    for (size_t t = begin; t < end; ++t)
      for (const uint32_t v : triangles[t]) {
        lo = std::min(lo, v);
        hi = std::max(hi, v);
      }
    range[static_cast<size_t>(k)] = {lo, hi};
  });
  // The part of vertex v among `count` equal parts (part q begins at n q / count).
  const auto part_of = [&](uint32_t v, int64_t count) {
    const size_t c = static_cast<size_t>(count);
    size_t q = static_cast<size_t>(v) * c / n;
    while (q + 1 < c && n * (q + 1) / c <= v) ++q;
    while (q > 0 && n * q / c > v) --q;
    return static_cast<int64_t>(q);
  };
  const auto reads = [&](int64_t count) {
    int64_t sum = 0;
    for (const auto& r : range) sum += part_of(r[1], count) - part_of(r[0], count) + 1;
    return sum;
  };
  // As many parts as balance the threads, halved while they would read more than twice the
  // triangles between them; down to the few parts that may each read all of them.
  const int64_t full_read_parts = std::min(thread_count(), kMostFullReadParts);
  int64_t count = std::min<int64_t>({4 * thread_count(), kMostParts, static_cast<int64_t>(n)});
  while (count > full_read_parts && reads(count) > 2 * chunk_count) count = std::max(count / 2, full_read_parts);
  equal_parts(count);
  plan.every_triangle = false;
  plan.first_chunk.assign(static_cast<size_t>(count) + 1, 0);
  for (const auto& r : range)
    for (int64_t q = part_of(r[0], count); q <= part_of(r[1], count); ++q)
      ++plan.first_chunk[static_cast<size_t>(q) + 1];
  for (size_t q = 0; q < static_cast<size_t>(count); ++q) plan.first_chunk[q + 1] += plan.first_chunk[q];
  plan.chunks.resize(plan.first_chunk.back());
  std::vector<uint32_t> at(plan.first_chunk.begin(), plan.first_chunk.end() - 1);
  for (size_t k = 0; k < range.size(); ++k)
    for (int64_t q = part_of(range[k][0], count); q <= part_of(range[k][1], count); ++q)
      plan.chunks[at[static_cast<size_t>(q)]++] = static_cast<uint32_t>(k);
  return plan;
}

}  // namespace isotope
