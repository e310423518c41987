#include "engine/extract/slab_march.h"

#include <algorithm>
#include <chrono>
#include <memory>
#include <mutex>
#include <numeric>
#include <optional>
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
  builders.give(std::move(builder));
  return slab;
}

// Joins the slabs' meshes, handed to it in order. A vertex of slab s on its bottom plane takes the
// index slab s - 1 gave it; any other vertex is new, in slab s's order. Since slab s - 1 came
// first in the serial walk, that is the serial walk's first-appearance numbering exactly.
class SlabMerger {
 public:
  // Frees the slab.
  void append(Slab& s) {
    if (out_.positions.empty()) {  // nothing before it to share with: its numbering is the output's
      out_ = std::move(s.mesh);
      remap_.resize(out_.positions.size());
      std::iota(remap_.begin(), remap_.end(), 0u);
    } else {
      remap_.assign(s.mesh.positions.size(), EdgeVertexMap::kAbsent);
      for (const PlaneVertex& v : s.bottom)
        remap_[v.local] = previous_top_.find_or_insert(v.key, EdgeVertexMap::kAbsent);
      for (size_t k = 0; k < remap_.size(); ++k)
        if (remap_[k] == EdgeVertexMap::kAbsent) {
          remap_[k] = static_cast<uint32_t>(out_.positions.size());
          out_.positions.push_back(s.mesh.positions[k]);
        }
      for (const auto& t : s.mesh.triangles) out_.triangles.push_back({remap_[t[0]], remap_[t[1]], remap_[t[2]]});
    }
    EdgeVertexMap top(s.top.size());
    for (const PlaneVertex& v : s.top) top.find_or_insert(v.key, remap_[v.local]);
    previous_top_ = std::move(top);
    s = Slab{};
  }
  Mesh take() { return std::move(out_); }

 private:
  Mesh out_;
  EdgeVertexMap previous_top_{0};  // edge key -> output index, on the plane below the next slab
  std::vector<uint32_t> remap_;    // the current slab's vertex -> output index
};

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
    SlabMerger merger;
    settle_together(group, [&] {
      for (Slab& s : mine) merger.append(s);
    });
    return merger.take();
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
  SlabMerger merger;
  settle_together(group, [&] {
    for (std::vector<uint8_t>& bytes : all) {
      ByteReader r(bytes);
      const auto n = r.get<uint64_t>();
      for (uint64_t i = 0; i < n; ++i) {
        Slab s;
        r.get_array(s.mesh.positions);
        r.get_array(s.mesh.triangles);
        r.get_array(s.bottom);
        r.get_array(s.top);
        merger.append(s);
      }
      bytes = {};
    }
  });
  return merger.take();
}

Mesh march_in_slabs(const SlabPlan& plan, const MarchSlab& march, const std::function<void()>& on_failure) {
  const int64_t count = slab_count(plan);
  if (count <= 0) return Mesh{};
  // Each slab is merged as soon as it and all before it are done, by the thread that finished the
  // last of them (the others go on extracting): only the slabs in flight or waiting for an earlier
  // one are held, not the whole mesh twice. Slabs are handed out in order, so few wait.
  SlabMerger merger;
  std::vector<std::optional<Slab>> done(static_cast<size_t>(count));
  std::mutex mutex;
  int64_t next = 0;      // the next slab to merge
  bool merging = false;  // a thread is merging, and takes any slab that becomes next meanwhile
  BuilderPool builders;  // a welding table per thread while the slabs are marched and merged
  parallel_for_in_order(int64_t{0}, count, [&](int64_t s) {
    try {
      const int64_t z_begin = s * plan.slab_layers, z_end = std::min(z_begin + plan.slab_layers, plan.cell_layers);
      Slab slab = extract_slab(plan, march, builders, z_begin, z_end, s > 0, s + 1 < count);
      std::unique_lock<std::mutex> lock(mutex);
      done[static_cast<size_t>(s)] = std::move(slab);
      if (merging) return;
      merging = true;
      while (next < count && done[static_cast<size_t>(next)]) {
        Slab ready = std::move(*done[static_cast<size_t>(next)]);
        done[static_cast<size_t>(next++)].reset();
        lock.unlock();
        try {
          merger.append(ready);
        } catch (...) {
          lock.lock();
          merging = false;  // the next slab's thread may try: the first failure is the one thrown
          throw;
        }
        lock.lock();
      }
      merging = false;
    } catch (...) {
      if (on_failure) on_failure();
      throw;
    }
  });
  return merger.take();
}

}  // namespace isotope
