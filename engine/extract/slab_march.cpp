#include "engine/extract/slab_march.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <deque>
#include <memory>
#include <mutex>
#include <new>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "engine/core/gather_items.h"
#include "engine/core/huge_blocks.h"
#include "engine/core/lending_pool.h"
#include "engine/core/parallel.h"
#include "engine/extract/block_march.h"
#include "engine/mesh/edge_vertex_map.h"
#include "isotope/error.h"

namespace isotope {
namespace {

// A vertex that the neighbouring slab may also have: its index in its slab and its edge key.
using PlaneVertex = MeshBuilder::PlaneVertex;

struct Slab {
  Mesh mesh;
  // Vertices on the plane shared with the slab below (bottom) and above (top), in vertex order.
  std::vector<PlaneVertex> bottom, top;
};

// A slab's builder is lent from slab to slab (LendingPool): its welding table (the full-resolution
// baseline's; the block march welds in its own memo) grows to hundreds of thousands of slots, and a
// table per slab was fresh memory, grown by doubling, every time (docs/METHOD.md, "eps = 0 by
// blocks").
using BuilderPool = LendingPool<MeshBuilder>;

// A slab's builder, and the memory its mesh is built in, come from these: both are lent from slab
// to slab, since fresh memory costs more than the march that fills it (docs/METHOD.md, "eps = 0 by
// blocks").
struct SlabMemory {
  BuilderPool builders;
  LendingPool<Mesh> meshes;        // arrays of slabs already joined, for later slabs to be built in
  bool joined_as_marched = false;  // meshes are given back while slabs are marched
};

size_t bytes_of(const Mesh& m) {
  return m.positions.capacity() * sizeof(m.positions[0]) + m.triangles.capacity() * sizeof(m.triangles[0]);
}

// The slab memory one extraction leaves to the next in the same process (a Python session, the
// server, a C++ loop), up to kKeptSlabBytes: the slabs' arrays are below malloc's threshold for
// mappings of their own, and malloc hands the heap's freed top back to the kernel, so without it
// every extraction built its slabs in fresh pages again (docs/METHOD.md, "eps = 0 by blocks"). One
// is kept; an extraction that finds none (another is running) makes its own.
class SlabMemoryShelf {
 public:
  static constexpr size_t kKeptSlabBytes = size_t{64} << 20;

  std::unique_ptr<SlabMemory> take() {
    {
      const std::lock_guard<std::mutex> lock(mutex_);
      if (kept_) return std::move(kept_);
    }
    return std::make_unique<SlabMemory>();
  }
  // MEMORY's builders, as many as fit in kKeptSlabBytes: before the last slabs are copied, so that
  // the others are gone before the mesh's last pages are touched. Returns their bytes.
  static size_t trim_builders(SlabMemory& memory) {
    return memory.builders.keep_at_most(kKeptSlabBytes, [](const MeshBuilder& b) { return b.bytes(); });
  }
  // MEMORY's builders (trimmed), then its meshes, as many as fit in kKeptSlabBytes.
  void put(std::unique_ptr<SlabMemory> memory) {
    const size_t builders = trim_builders(*memory);
    memory->meshes.keep_at_most(kKeptSlabBytes - builders, [](const Mesh& m) { return bytes_of(m); });
    const std::lock_guard<std::mutex> lock(mutex_);
    if (!kept_) kept_ = std::move(memory);
  }
  void clear() {
    std::unique_ptr<SlabMemory> given_back;
    const std::lock_guard<std::mutex> lock(mutex_);
    given_back = std::move(kept_);
  }

 private:
  std::mutex mutex_;
  std::unique_ptr<SlabMemory> kept_;
};

SlabMemoryShelf& slab_memory_shelf() {
  static SlabMemoryShelf* shelf = new SlabMemoryShelf;  // never destroyed: an extraction may end at exit
  return *shelf;
}

// Slab s's cell layers, [z_begin, z_end).
std::pair<int64_t, int64_t> slab_range(const SlabPlan& plan, int64_t s) {
  const int64_t z_begin = s * plan.slab_layers;
  return {z_begin, std::min(z_begin + plan.slab_layers, plan.cell_layers)};
}

// One slab's own welded mesh. Only an edge lying in the plane z = z0 between two slabs can be cut
// in both (its p + q has z 2 z0; every other edge has both ends in one slab), so those vertices
// are the only ones the merge has to look up.
Slab extract_slab(const SlabPlan& plan, const MarchSlab& march, SlabMemory& memory, int64_t z_begin, int64_t z_end,
                  bool below, bool above) {
  std::unique_ptr<MeshBuilder> builder = memory.builders.take([] { return std::unique_ptr<MeshBuilder>(); });
  if (builder)
    builder->retarget(plan.iso, plan.side, plan.origin, plan.spacing);
  else
    builder = std::make_unique<MeshBuilder>(plan.iso, plan.side, plan.origin, plan.spacing);
  if (std::unique_ptr<Mesh> storage = memory.meshes.take([] { return nullptr; }))
    builder->build_in(std::move(*storage));
  builder->keep_plane_keys(below ? 2 * z_begin : -1, above ? 2 * z_end : -1);
  march(z_begin, z_end, *builder);
  Slab slab{builder->take(), builder->take_bottom_keys(), builder->take_top_keys()};
  builder->reset();
  // Without joined slabs' arrays to build in, the next slab is about as large: room for a quarter
  // more. Only a hint: without the memory for it, the next mesh grows as it goes.
  const size_t vertices = slab.mesh.positions.size(), triangles = slab.mesh.triangles.size();
  try {
    if (!memory.joined_as_marched) builder->reserve(vertices + vertices / 4, triangles + triangles / 4);
  } catch (const std::bad_alloc&) {
  }
  memory.builders.give(std::move(builder));
  return slab;
}

// Numbers the slabs' vertices as one walk over the slabs in order does: a vertex of slab s on its
// bottom plane takes the index slab s - 1 gave it; any other vertex is new, in slab s's order.
// Since slab s - 1 comes first in the serial walk, that is the serial walk's first-appearance
// numbering exactly. It looks only at the planes between slabs, one slab after another; then the
// slab knows where its vertices and triangles go (its Place), and is copied there.
class SlabNumbering {
 public:
  static constexpr uint32_t kAbsent = EdgeVertexMap::kAbsent;
  struct Place {
    uint32_t first_vertex = 0;  // the output index of the slab's first new vertex
    size_t new_vertices = 0;    // the slab's vertices less those the slab below gave
    size_t first_triangle = 0;
    std::vector<uint32_t> bottom;  // per bottom vertex: its index in the slab below, or kAbsent
  };

  // The next slab's place. Throws std::length_error once the vertices outgrow 32-bit indices.
  Place next(const Slab& slab) {
    Place place;
    place.first_vertex = static_cast<uint32_t>(vertices_);
    place.first_triangle = triangles_;
    place.bottom.resize(slab.bottom.size());
    size_t found = 0;
    for (size_t i = 0; i < slab.bottom.size(); ++i) {
      place.bottom[i] = below_.find_or_insert(slab.bottom[i].key, kAbsent);
      found += place.bottom[i] != kAbsent;
    }
    // A top vertex is new (the planes differ): its index is the slab's first plus the new vertices
    // before it, i.e. its own index less the bottom vertices found before it (both lists are in
    // vertex order).
    EdgeVertexMap top(slab.top.size());
    size_t b = 0, found_before = 0;
    for (const PlaneVertex& v : slab.top) {
      for (; b < slab.bottom.size() && slab.bottom[b].local < v.local; ++b) found_before += place.bottom[b] != kAbsent;
      top.find_or_insert(v.key, static_cast<uint32_t>(vertices_ + v.local - found_before));
    }
    below_ = std::move(top);
    place.new_vertices = slab.mesh.positions.size() - found;
    vertices_ += place.new_vertices;
    triangles_ += slab.mesh.triangles.size();
    if (vertices_ >= kAbsent)
      throw Error("the mesh has " + std::to_string(vertices_) + " vertices, more than its 32-bit indices can number");
    return place;
  }
  size_t vertices() const { return vertices_; }
  size_t triangles() const { return triangles_; }

 private:
  EdgeVertexMap below_{0};  // edge key -> output index, on the plane below the next slab
  size_t vertices_ = 0, triangles_ = 0;
};

// Copies SLAB where PLACE says into the mesh's arrays, which have room up to the place's end.
void copy_slab(const Slab& slab, const SlabNumbering::Place& place, std::array<float, 3>* positions,
               std::array<uint32_t, 3>* triangles) {
  // The slab's stretch of the mesh is faulted in by one call before it is written (docs/METHOD.md,
  // "Fresh memory"): its pages are fresh, and their faults one at a time in the copies below took
  // a fifth of a one-shot eps 0's processor time.
  detail::prefault(positions + place.first_vertex, place.new_vertices * sizeof(positions[0]));
  detail::prefault(triangles + place.first_triangle, slab.mesh.triangles.size() * sizeof(triangles[0]));
  // Kept by the thread from slab to slab: a fresh one per slab took its pages' faults each time.
  thread_local std::vector<uint32_t> remap;
  remap.resize(slab.mesh.positions.size());  // every entry written below
  uint32_t next = place.first_vertex;
  size_t b = 0;
  for (size_t k = 0; k < remap.size(); ++k) {
    if (b < slab.bottom.size() && slab.bottom[b].local == k) {
      const uint32_t index_below = place.bottom[b++];
      if (index_below != SlabNumbering::kAbsent) {
        remap[k] = index_below;
        continue;
      }
    }
    remap[k] = next;
    positions[next++] = slab.mesh.positions[k];
  }
  auto* to = triangles + place.first_triangle;
  for (const auto& t : slab.mesh.triangles) *to++ = {remap[t[0]], remap[t[1]], remap[t[2]]};
}

// Joins the slabs' meshes in slab order, all marched: numbered first, alone; then the slabs are
// copied into a mesh of the exact size on all threads, each page of it first touched by the
// thread that writes it. (Appending each slab to a mesh that grew by doubling copied every vertex
// and triangle again, about once on average, into fresh pages, on one thread, after the last
// slab's march: docs/METHOD.md, "eps = 0 by blocks".) Frees the slabs.
Mesh join_slabs(std::vector<Slab>& slabs) {
  SlabNumbering numbering;
  std::vector<SlabNumbering::Place> places;
  places.reserve(slabs.size());
  for (const Slab& slab : slabs) places.push_back(numbering.next(slab));
  Mesh out;
  out.positions.resize(numbering.vertices());
  out.triangles.resize(numbering.triangles());
  parallel_for(0, static_cast<int64_t>(slabs.size()), [&](int64_t s) {
    Slab& slab = slabs[static_cast<size_t>(s)];
    copy_slab(slab, places[static_cast<size_t>(s)], out.positions.data(), out.triangles.data());
    slab = Slab{};
  });
  return out;
}

// An array's room, reserved as address space only (detail::AddressSpaceOnly), for a mesh being
// joined whose size is not known yet: only what the slabs fill costs memory. Once the size is known
// the room becomes the mesh's array, the address space beyond it given back. The room starts on the
// pages of the same array of a mesh freed before, where one was kept (detail::AddressSpaceOnly).
template <class T>
class Reserved {
 public:
  // PURPOSE: detail::AddressSpaceOnly's, one per array of the mesh.
  Reserved(size_t count, int purpose) {  // throws std::bad_alloc
    const detail::AddressSpaceOnly address_space_only(purpose);
    data_ = static_cast<T*>(detail::allocate_huge(count * sizeof(T)));
    count_ = count;
  }
  ~Reserved() { detail::free_huge(data_); }
  Reserved(const Reserved&) = delete;
  Reserved& operator=(const Reserved&) = delete;

  T* data() const { return data_; }
  size_t count() const { return count_; }

  // ARRAY becomes the first N elements: this room itself, or (under a huge page, which an array
  // that small takes from malloc) a copy of them.
  void hand_to(Mesh::Array<T>& array, size_t n) {
    detail::shrink_reservation(data_, n * sizeof(T));
    {
      const detail::AdoptReservation adopt(data_);
      try {
        array.reserve(n);
      } catch (...) {
        if (adopt.adopted()) data_ = nullptr;  // the array's, and freed with it
        throw;
      }
      if (adopt.adopted()) data_ = nullptr;
    }
    array.resize(n);  // writes nothing (Mesh::Array's allocator): what the slabs wrote stays
    if (data_ != nullptr && n > 0) std::copy(data_, data_ + n, array.data());
  }

 private:
  T* data_ = nullptr;
  size_t count_ = 0;
};

// The most vertices and triangles the slabs of PLAN can make: 7 vertices a node (its edges along
// the axes, the face diagonals and the body diagonal of Kuhn's cells) and 12 triangles a cell (6
// tetrahedra of at most 2). Nullopt when that is more than a quarter of the 47-bit address space.
std::optional<std::pair<size_t, size_t>> mesh_bound(const SlabPlan& plan) {
  const auto nodes = [&](int k) {
    return static_cast<double>(plan.layer_nodes[k] > 0 ? plan.layer_nodes[k] : plan.side);
  };
  const double layers = static_cast<double>(plan.cell_layers);
  const double vertices = std::min(7 * nodes(0) * nodes(1) * (layers + 1), double{SlabNumbering::kAbsent});
  const double triangles = 12 * std::max(nodes(0) - 1, 1.0) * std::max(nodes(1) - 1, 1.0) * layers;
  if (12 * (vertices + triangles) > 0x1p45) return std::nullopt;
  return std::pair{static_cast<size_t>(vertices), static_cast<size_t>(triangles)};
}

}  // namespace

void give_back_slab_memory() {
  slab_memory_shelf().clear();
  give_back_edge_memos();
}

Mesh march_in_slabs(const SlabPlan& plan, const MarchSlab& march, const Distribution& group, int64_t first,
                    int64_t last, double* seconds, bool keep_share, const std::function<void()>& on_failure) {
  const int64_t count = slab_count(plan);
  std::vector<Slab> mine(static_cast<size_t>(last - first));
  settle_together(group, [&] {
    SlabMemory memory;  // gone before the slabs are sent and merged
    const auto start = std::chrono::steady_clock::now();
    parallel_for_in_order(first, last, [&](int64_t s) {
      const auto [z_begin, z_end] = slab_range(plan, s);
      try {
        mine[static_cast<size_t>(s - first)] = extract_slab(plan, march, memory, z_begin, z_end, s > 0, s + 1 < count);
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
  std::vector<Slab> slabs = gather_items(
      group, mine,
      [](ByteWriter& w, const Slab& s) {
        put_mesh(w, s.mesh);
        w.put_array(s.bottom);
        w.put_array(s.top);
      },
      [](ByteReader& r, Slab& s) {
        get_mesh(r, s.mesh);
        r.get_array(s.bottom);
        r.get_array(s.top);
      });
  Mesh mesh;
  settle_together(group, [&] { mesh = join_slabs(slabs); });
  return mesh;
}

Mesh march_in_slabs(const SlabPlan& plan, const MarchSlab& march, const std::function<void()>& on_failure) {
  const int64_t count = slab_count(plan);
  if (count <= 0) return Mesh{};
  // The mesh's room, reserved for the most the slabs can make; where the address space is not there
  // (the bound past what may be reserved, or a `ulimit -v`), the slabs are all marched, then joined.
  std::optional<Reserved<std::array<float, 3>>> positions;
  std::optional<Reserved<std::array<uint32_t, 3>>> triangles;
  try {
    if (const auto bound = mesh_bound(plan)) {
      positions.emplace(bound->first, 1);
      triangles.emplace(bound->second, 2);
    }
  } catch (const std::bad_alloc&) {
    positions.reset();
  }
  if (!positions || !triangles) {
    std::vector<Slab> slabs(static_cast<size_t>(count));
    {
      SlabMemory memory;  // a welding table per thread; gone before the mesh is allocated
      parallel_for_in_order(int64_t{0}, count, [&](int64_t s) {
        try {
          const auto [z_begin, z_end] = slab_range(plan, s);
          slabs[static_cast<size_t>(s)] = extract_slab(plan, march, memory, z_begin, z_end, s > 0, s + 1 < count);
        } catch (...) {
          if (on_failure) on_failure();
          throw;
        }
      });
    }
    return join_slabs(slabs);
  }
  // Each slab numbered as soon as it and every slab before it are marched, then copied into the
  // mesh reserved above by the next thread to start a slab (or, at the end, by all), and its arrays
  // lent to a slab after it: of the slabs' meshes, only those of the slabs in flight are ever held,
  // the mesh is the only fresh memory the join writes, and its first touch is spread over the
  // threads while they march.
  const int64_t window = 2 * thread_count() + 2;
  std::vector<Slab> in_flight(static_cast<size_t>(window));
  std::unique_ptr<SlabMemory> kept = slab_memory_shelf().take();
  SlabMemory& memory = *kept;
  memory.joined_as_marched = true;
  SlabNumbering numbering;
  struct Numbered {
    Slab slab;
    SlabNumbering::Place place;
  };
  std::mutex numbered_mutex;
  std::deque<Numbered> numbered;  // numbered, not copied yet
  const auto copy_one = [&] {
    Numbered n;
    {
      const std::lock_guard<std::mutex> lock(numbered_mutex);
      if (numbered.empty()) return false;
      n = std::move(numbered.front());
      numbered.pop_front();
    }
    copy_slab(n.slab, n.place, positions->data(), triangles->data());
    memory.meshes.give(std::make_unique<Mesh>(std::move(n.slab.mesh)));
    return true;
  };
  parallel_in_order_committed(
      int64_t{0}, count, window,
      [&](int64_t s) {
        try {
          copy_one();
          const auto [z_begin, z_end] = slab_range(plan, s);
          in_flight[static_cast<size_t>(s % window)] =
              extract_slab(plan, march, memory, z_begin, z_end, s > 0, s + 1 < count);
        } catch (...) {
          if (on_failure) on_failure();
          throw;
        }
      },
      [&](int64_t s) {
        Slab& slab = in_flight[static_cast<size_t>(s % window)];
        try {
          SlabNumbering::Place place = numbering.next(slab);
          Numbered n{std::move(slab), std::move(place)};
          if (numbering.vertices() > positions->count() || numbering.triangles() > triangles->count())
            throw std::logic_error("a slab made more than a cell's most triangles or a node's most vertices");
          const std::lock_guard<std::mutex> lock(numbered_mutex);
          numbered.push_back(std::move(n));
        } catch (...) {
          if (on_failure) on_failure();
          throw;
        }
        slab = Slab{};
      });
  SlabMemoryShelf::trim_builders(memory);
  parallel_for(int64_t{0}, static_cast<int64_t>(numbered.size()), [&](int64_t) { copy_one(); });
  slab_memory_shelf().put(std::move(kept));
  Mesh mesh;
  positions->hand_to(mesh.positions, numbering.vertices());
  triangles->hand_to(mesh.triangles, numbering.triangles());
  return mesh;
}

}  // namespace isotope
