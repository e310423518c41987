#pragma once
// Items of every process gathered on rank 0, in rank order, each written into the bytes sent and
// read back one by one: what the joins of a distributed extraction send (the slabs at eps 0, the
// pieces above it). And a mesh's arrays as those items carry them.
#include <cstdint>
#include <vector>

#include "engine/core/byte_codec.h"
#include "isotope/distribution.h"
#include "isotope/mesh.h"

namespace isotope {

inline void put_mesh(ByteWriter& w, const Mesh& mesh) {
  w.put_array(mesh.positions);
  w.put_array(mesh.triangles);
}
inline void get_mesh(ByteReader& r, Mesh& mesh) {
  r.get_array(mesh.positions);
  r.get_array(mesh.triangles);
}

// MINE from every rank, in rank order, on rank 0; every other rank gets none. Each item is written
// by PUT(ByteWriter&, const T&) and freed at once, and read back by GET(ByteReader&, T&). Collective.
// Each step settles together (settle_together): the copy may run out of memory on
// one rank alone, and so may rank 0 receiving or reading back.
template <class T, class Put, class Get>
std::vector<T> gather_items(const Distribution& group, std::vector<T>& mine, const Put& put, const Get& get) {
  ByteWriter w;
  settle_together(group, [&] {
    w.put(static_cast<uint64_t>(mine.size()));
    for (T& item : mine) {
      put(w, item);
      item = T{};
    }
  });
  std::vector<std::vector<uint8_t>> all;
  settle_together(group, [&] { all = group.gather(w.bytes()); });
  w = ByteWriter{};
  std::vector<T> items;
  settle_together(group, [&] {
    for (std::vector<uint8_t>& bytes : all) {
      ByteReader r(bytes);
      const auto n = r.get<uint64_t>();
      for (uint64_t i = 0; i < n; ++i) get(r, items.emplace_back());
      bytes = {};
    }
  });
  return items;
}

}  // namespace isotope
