#include "engine/extract/slab_march.h"

#include <algorithm>
#include <chrono>
#include <memory>
#include <new>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "engine/core/byte_codec.h"
#include "engine/core/lending_pool.h"
#include "engine/core/parallel.h"
#include "engine/mesh/edge_vertex_map.h"

namespace isotope {
namespace {

// A vertex that the neighbouring slab may also have: its index in its slab and its edge key.
using PlaneVertex = MeshBuilder::PlaneVertex;

struct Slab {
  Mesh mesh;
  // Vertices on the plane shared with the slab below (bottom) and above (top), in vertex order.
  std::vector<PlaneVertex> bottom, top;
};

// A slab's builder is lent from slab to slab (LendingPool): its welding table grows to hundreds of
// thousands of slots, and a table per slab was fresh memory, grown by doubling, every time
// (docs/METHOD.md, "eps = 0 by blocks").
using BuilderPool = LendingPool<MeshBuilder>;

// One slab's own welded mesh. Only an edge lying in the plane z = z0 between two slabs can be cut
// in both (its p + q has z 2 z0; every other edge has both ends in one slab), so those vertices
// are the only ones the merge has to look up.
Slab extract_slab(const SlabPlan& plan, const MarchSlab& march, BuilderPool& builders, int64_t z_begin, int64_t z_end,
                  bool below, bool above) {
  std::unique_ptr<MeshBuilder> builder =
      builders.take([&] { return std::make_unique<MeshBuilder>(plan.iso, plan.side, plan.origin, plan.spacing); });
  builder->keep_plane_keys(below ? 2 * z_begin : -1, above ? 2 * z_end : -1);
  march(z_begin, z_end, *builder);
  Slab slab{builder->take(), builder->take_bottom_keys(), builder->take_top_keys()};
  builder->reset();
  // The next slab is about as large: room for a quarter more. Only a hint: without the memory for
  // it, the next mesh grows as it goes.
  const size_t vertices = slab.mesh.positions.size(), triangles = slab.mesh.triangles.size();
  try {
    builder->reserve(vertices + vertices / 4, triangles + triangles / 4);
  } catch (const std::bad_alloc&) {
  }
  builders.give(std::move(builder));
  return slab;
}

// Joins the slabs' meshes in slab order. A vertex of slab s on its bottom plane takes the index
// slab s - 1 gave it; any other vertex is new, in slab s's order. Since slab s - 1 comes first in
// the serial walk, that is the serial walk's first-appearance numbering exactly. The numbering
// looks only at the planes between slabs, so it runs first, alone; then every slab knows where
// its vertices and triangles go, and the slabs are copied into a mesh of the exact size on all
// threads, each page of it first touched by the thread that writes it. (Appending each slab to a
// mesh that grew by doubling copied every vertex and triangle again, about once on average, into
// fresh pages, on one thread, after the last slab's march: docs/METHOD.md, "eps = 0 by blocks".)
// Frees the slabs.
Mesh join_slabs(std::vector<Slab>& slabs) {
  constexpr uint32_t kAbsent = EdgeVertexMap::kAbsent;
  struct Place {
    uint32_t first_vertex = 0;  // the output index of the slab's first new vertex
    size_t first_triangle = 0;
    std::vector<uint32_t> bottom;  // per bottom vertex: its index in the slab below, or kAbsent
  };
  std::vector<Place> places(slabs.size());
  size_t vertices = 0, triangles = 0;
  EdgeVertexMap below(0);  // edge key -> output index, on the plane below the slab
  for (size_t s = 0; s < slabs.size(); ++s) {
    const Slab& slab = slabs[s];
    Place& place = places[s];
    place.first_vertex = static_cast<uint32_t>(vertices);
    place.first_triangle = triangles;
    place.bottom.resize(slab.bottom.size());
    size_t found = 0;
    for (size_t i = 0; i < slab.bottom.size(); ++i) {
      place.bottom[i] = below.find_or_insert(slab.bottom[i].key, kAbsent);
      found += place.bottom[i] != kAbsent;
    }
    // A top vertex is new (the planes differ): its index is the slab's first plus the new vertices
    // before it, i.e. its own index less the bottom vertices found before it (both lists are in
    // vertex order).
    EdgeVertexMap top(slab.top.size());
    size_t b = 0, found_before = 0;
    for (const PlaneVertex& v : slab.top) {
      for (; b < slab.bottom.size() && slab.bottom[b].local < v.local; ++b) found_before += place.bottom[b] != kAbsent;
      top.find_or_insert(v.key, static_cast<uint32_t>(vertices + v.local - found_before));
    }
    below = std::move(top);
    vertices += slab.mesh.positions.size() - found;
    triangles += slab.mesh.triangles.size();
  }
  if (vertices >= kAbsent)
    throw std::length_error("the mesh has " + std::to_string(vertices) +
                            " vertices, more than its 32-bit indices can number");
  Mesh out;
  out.positions.resize(vertices);
  out.triangles.resize(triangles);
  parallel_for(0, static_cast<int64_t>(slabs.size()), [&](int64_t s) {
    Slab& slab = slabs[static_cast<size_t>(s)];
    const Place& place = places[static_cast<size_t>(s)];
    std::vector<uint32_t> remap(slab.mesh.positions.size());
    uint32_t next = place.first_vertex;
    size_t b = 0;
    for (size_t k = 0; k < remap.size(); ++k) {
      if (b < slab.bottom.size() && slab.bottom[b].local == k) {
        const uint32_t index_below = place.bottom[b++];
        if (index_below != kAbsent) {
          remap[k] = index_below;
          continue;
        }
      }
      remap[k] = next;
      out.positions[next++] = slab.mesh.positions[k];
    }
    auto* to = out.triangles.data() + place.first_triangle;
    for (const auto& t : slab.mesh.triangles) *to++ = {remap[t[0]], remap[t[1]], remap[t[2]]};
    slab = Slab{};
  });
  return out;
}

}  // namespace

Mesh march_in_slabs(const SlabPlan& plan, const MarchSlab& march, const Distribution& group, int64_t first,
                    int64_t last, double* seconds, bool keep_share, const std::function<void()>& on_failure) {
  const int64_t count = slab_count(plan);
  std::vector<Slab> mine(static_cast<size_t>(last - first));
  settle_together(group, [&] {
    BuilderPool builders;  // gone before the slabs are sent and merged
    const auto start = std::chrono::steady_clock::now();
    parallel_for_in_order(first, last, [&](int64_t s) {
      const int64_t z_begin = s * plan.slab_layers, z_end = std::min(z_begin + plan.slab_layers, plan.cell_layers);
      try {
        mine[static_cast<size_t>(s - first)] =
            extract_slab(plan, march, builders, z_begin, z_end, s > 0, s + 1 < count);
      } catch (...) {
        if (on_failure) on_failure();
        throw;
      }
    });
    *seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  });
  if (keep_share) {
    Mesh mesh;
    settle_together(group, [&] { mesh = join_slabs(mine); });
    return mesh;
  }
  ByteWriter w;
  settle_together(group, [&] {  // the copy may run out of memory on one rank alone
    w.put(static_cast<uint64_t>(mine.size()));
    for (Slab& s : mine) {
      w.put_array(s.mesh.positions);
      w.put_array(s.mesh.triangles);
      w.put_array(s.bottom);
      w.put_array(s.top);
      s = Slab{};
    }
  });
  std::vector<std::vector<uint8_t>> all;
  settle_together(group, [&] { all = group.gather(w.bytes()); });  // rank 0 may run out of memory receiving
  w = ByteWriter{};
  Mesh mesh;
  settle_together(group, [&] {
    std::vector<Slab> slabs;
    for (std::vector<uint8_t>& bytes : all) {
      ByteReader r(bytes);
      const auto n = r.get<uint64_t>();
      for (uint64_t i = 0; i < n; ++i) {
        Slab& s = slabs.emplace_back();
        r.get_array(s.mesh.positions);
        r.get_array(s.mesh.triangles);
        r.get_array(s.bottom);
        r.get_array(s.top);
      }
      bytes = {};
    }
    mesh = join_slabs(slabs);
  });
  return mesh;
}

Mesh march_in_slabs(const SlabPlan& plan, const MarchSlab& march, const std::function<void()>& on_failure) {
  const int64_t count = slab_count(plan);
  if (count <= 0) return Mesh{};
  std::vector<Slab> slabs(static_cast<size_t>(count));
  BuilderPool builders;  // a welding table per thread
  parallel_for_in_order(int64_t{0}, count, [&](int64_t s) {
    try {
      const int64_t z_begin = s * plan.slab_layers, z_end = std::min(z_begin + plan.slab_layers, plan.cell_layers);
      slabs[static_cast<size_t>(s)] = extract_slab(plan, march, builders, z_begin, z_end, s > 0, s + 1 < count);
    } catch (...) {
      if (on_failure) on_failure();
      throw;
    }
  });
  builders.clear();  // their welding tables and reserved meshes, before the mesh is allocated
  return join_slabs(slabs);
}

}  // namespace isotope
