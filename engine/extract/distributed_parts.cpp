#include "engine/extract/distributed_parts.h"

#include <stdexcept>
#include <utility>

#include "engine/core/gather_items.h"
#include "isotope/error.h"

namespace isotope {

std::vector<double> share_costs(const Distribution& group, size_t n,
                                const std::function<void(size_t first, size_t last, double* out)>& compute) {
  const auto r = static_cast<size_t>(group.rank()), ranks = static_cast<size_t>(group.ranks());
  const size_t first = n * r / ranks, last = n * (r + 1) / ranks;
  std::vector<double> mine(last - first);
  settle_together(group, [&] { compute(first, last, mine.data()); });
  ByteWriter w;
  w.put_array(mine);
  std::vector<double> all;
  for (const std::vector<uint8_t>& bytes : group.all_gather(w.bytes())) {
    ByteReader rd(bytes);
    std::vector<double> part;
    rd.get_array(part);
    all.insert(all.end(), part.begin(), part.end());
  }
  if (all.size() != n) throw Error("the ranks disagree on the number of pieces");
  return all;
}

int64_t sum_over_ranks(const Distribution& group, int64_t mine) {
  ByteWriter w;
  w.put(mine);
  int64_t sum = 0;
  for (const std::vector<uint8_t>& bytes : group.all_gather(w.bytes())) {
    ByteReader r(bytes);
    sum += r.get<int64_t>();
  }
  return sum;
}

std::vector<RankLoad> gather_loads(const Distribution& group, const RankLoad& mine) {
  ByteWriter w;
  w.put(mine);
  std::vector<RankLoad> loads;
  for (const std::vector<uint8_t>& bytes : group.all_gather(w.bytes())) {
    ByteReader r(bytes);
    loads.push_back(r.get<RankLoad>());
  }
  return loads;
}

std::vector<PartMesh> gather_parts(const Distribution& group, std::vector<PartMesh> mine) {
  return gather_items(
      group, mine,
      [](ByteWriter& w, const PartMesh& p) {
        put_mesh(w, p.mesh);
        w.put_array(p.keys);
        w.put(p.tets_visited);
        w.put(p.tets_emitted);
        w.put(p.tets_simplified);
        w.put(p.region);
      },
      [](ByteReader& r, PartMesh& p) {
        get_mesh(r, p.mesh);
        r.get_array(p.keys);
        p.tets_visited = r.get<int64_t>();
        p.tets_emitted = r.get<int64_t>();
        p.tets_simplified = r.get<int64_t>();
        p.region = r.get<Tet>();
      });
}

}  // namespace isotope
