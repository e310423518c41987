// Invariant 5 of design.md, for the part that is parallel today: preprocessing with one
// thread and with every thread gives the same records, so the same mesh bit for bit.
#include <gtest/gtest.h>

#include <tbb/global_control.h>

#include "engine/extract.h"
#include "engine/fields.h"
#include "engine/multires_volume.h"
#include "tests/test_support.h"

namespace isotope {
namespace {

Mesh extract_with_threads(const Volume& v, const ExtractOptions& o, size_t threads) {
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
  return extract(MultiresVolume::build(v), o);
}

TEST(Determinism, OneThreadAndAllThreadsGiveTheSameMesh) {
  const Volume volumes[] = {generate_noise(33, 5), testing::crop(generate_algebraic(40), {40, 33, 37})};
  for (const Volume& v : volumes)
    for (double eps : {0.0, 0.02, 0.3}) {
      ExtractOptions o;
      o.eps = eps;
      const Mesh one = extract_with_threads(v, o, 1);
      const Mesh all = extract_with_threads(v, o, 8);
      ASSERT_GT(one.triangles.size(), 0u);
      EXPECT_EQ(one.positions, all.positions) << "eps " << eps;
      EXPECT_EQ(one.triangles, all.triangles) << "eps " << eps;
    }
}

}  // namespace
}  // namespace isotope
