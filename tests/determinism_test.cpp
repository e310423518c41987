// The parallel parts of the engine, preprocessing and extraction (pieces of the traversal welded
// in order): one thread and every thread give the same mesh bit for bit (invariant 5 of
// docs/DESIGN.md), and progress reports, made from any worker, reach the caller in order. Also run
// under TSan.
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <vector>

#include "engine/core/fields.h"
#include "engine/extract/extract.h"
#include "engine/hierarchy/multires_volume.h"
#include "tests/test_support.h"

namespace isotope {
namespace {

Mesh extract_with_threads(const Volume& v, const ExtractOptions& o, size_t threads) {
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
  return extract(MultiresVolume::build(v), o);
}

TEST(Determinism, OneThreadAndAllThreadsGiveTheSameMesh) {
  const Volume volumes[] = {generate_noise(33, 5), testing::crop(generate_algebraic(40), {40, 33, 37}),
                            testing::crop(generate_noise(9, 3), {2, 9, 5}),
                            testing::load_shared(testing::shared_volumes()[3])};
  for (const Volume& v : volumes)
    for (double eps : {0.0, 0.02, 0.3, 8.0}) {
      ExtractOptions o;
      o.eps = eps;
      o.iso = v.dims[0] == 70 ? 64.5f : 0.0f;  // bolt's suggested isovalue
      const Mesh one = extract_with_threads(v, o, 1);
      const Mesh all = extract_with_threads(v, o, 8);
      ASSERT_GT(one.triangles.size(), 0u);
      EXPECT_EQ(one.positions, all.positions) << "eps " << eps;
      EXPECT_EQ(one.triangles, all.triangles) << "eps " << eps;
    }
}

TEST(Determinism, ParallelPreprocessingReportsGrowingProgressUpToOne) {
  std::vector<double> seen;  // the callback is serialized by the reporter, so no lock here
  const MultiresVolume mv = MultiresVolume::build(generate_noise(65, 9), [&](double f) { seen.push_back(f); });
  ASSERT_FALSE(seen.empty());
  EXPECT_LE(seen.size(), 101u);
  for (size_t i = 1; i < seen.size(); ++i) EXPECT_GT(seen[i], seen[i - 1]);
  EXPECT_EQ(seen.back(), 1.0);
}

}  // namespace
}  // namespace isotope
