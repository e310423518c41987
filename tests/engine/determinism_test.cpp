// The parallel parts of the engine, preprocessing and extraction (pieces of the traversal welded
// in order): one thread and every thread give the same mesh bit for bit (invariant 5 of
// docs/DESIGN.md), and progress reports, made from any worker, reach the caller in order. Also run
// under TSan.
#include <gtest/gtest.h>
#include <tbb/global_control.h>
#include <tbb/task_arena.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <future>
#include <memory>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "engine/core/lending_pool.h"
#include "engine/core/parallel.h"
#include "engine/extract/adaptive_extract.h"
#include "engine/extract/extract_drivers.h"
#include "engine/hierarchy/multires_volume.h"
#include "engine/synthetic/fields.h"
#include "tests/support/test_support.h"

namespace isotope {
namespace {

// The traversal is cut into pieces at level 6 (a few hundred), or on a small lattice higher up, so
// that each piece spans at least 15 levels (2^15 finest tetrahedra), down to level 3; a lattice
// with fewer levels than that is cut at its finest.
TEST(Pieces, ASmallLatticeIsCutHigherUpSoThatEachPieceSpansFifteenLevels) {
  const auto level_for = [](int64_t side) { return piece_level(Lattice::enclosing({side, side, side})); };
  EXPECT_EQ(level_for(1025), 6);
  EXPECT_EQ(level_for(129), 6);                                // k = 7: 21 levels
  EXPECT_EQ(level_for(65), 3);                                 // k = 6: 18 levels
  EXPECT_EQ(level_for(64), 3);                                 // hydrogen's 64^3 takes the same lattice
  EXPECT_EQ(level_for(17), 3);                                 // k = 4: 12 levels
  EXPECT_EQ(level_for(2), 0);                                  // one cell: 0 levels
  EXPECT_EQ(piece_level(Lattice::enclosing({129, 5, 5})), 6);  // the largest side decides
}

// The loop behind the banded build's tiles: builds run ahead of the commits by at most a window
// (each in its slot, never two at once in one), commits come in order, and a failed build stops
// the loop without a hang.
TEST(Determinism, BuildsRunAtMostAWindowAheadOfCommitsThatComeInOrder) {
  for (int threads : {1, 2, 4})
    for (int64_t window : {1, 2, 3}) {
      SCOPED_TRACE(::testing::Message() << threads << " threads, window " << window);
      tbb::global_control limit(tbb::global_control::max_allowed_parallelism, static_cast<size_t>(threads));
      std::atomic<int64_t> committed{0};
      std::vector<std::atomic<int>> busy(static_cast<size_t>(window));
      std::atomic<int> ahead{0}, clashes{0};
      std::vector<int64_t> order;
      parallel_in_order_committed(
          0, 120, window,
          [&](int64_t i) {
            if (i >= committed + window) ++ahead;
            std::atomic<int>& slot = busy[static_cast<size_t>(i % window)];
            if (slot.exchange(1)) ++clashes;
            if (i % 5 == 0) std::this_thread::sleep_for(std::chrono::microseconds(300));  // a long one
            slot = 0;
          },
          [&](int64_t i) {
            order.push_back(i);
            committed = i + 1;
          });
      std::vector<int64_t> expected(120);
      for (int64_t i = 0; i < 120; ++i) expected[static_cast<size_t>(i)] = i;
      EXPECT_EQ(order, expected);
      EXPECT_EQ(ahead, 0);
      EXPECT_EQ(clashes, 0);

      order.clear();
      EXPECT_THROW(parallel_in_order_committed(
                       0, 120, window,
                       [&](int64_t i) {
                         if (i == 37) throw std::runtime_error("tile 37");
                       },
                       [&](int64_t i) { order.push_back(i); }),
                   std::runtime_error);
      ASSERT_LT(order.size(), 38u);  // nothing after the failed build
      for (size_t i = 0; i < order.size(); ++i) EXPECT_EQ(order[i], static_cast<int64_t>(i));
    }
}

// A commit holds up no build: one that a build finishes during is only noted, and its thread goes
// on to the next build (the eps-0 march joins its slabs this way while the other threads march).
// A commit that throws stops the loop as a failed build does.
TEST(Determinism, BuildsGoOnWhileACommitRuns) {
  const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 2);
  const bool two_threads = tbb::this_task_arena::max_concurrency() >= 2;
  std::atomic<bool> started_2{false}, committing{false};
  std::atomic<int> overlapping_commits{0};
  bool build_2_ran_during_commit_0 = false;
  parallel_in_order_committed(
      0, 40, 4,
      [&](int64_t i) {
        if (i == 1) std::this_thread::sleep_for(std::chrono::milliseconds(20));  // done during commit 0
        if (i == 2) started_2 = true;
      },
      [&](int64_t i) {
        if (committing.exchange(true)) ++overlapping_commits;
        // Commit 0 waits for build 2, which the other thread starts once it has noted build 1
        // done: with commits under the lock, it could not note it before this commit ended.
        if (i == 0 && two_threads) {
          for (int ms = 0; ms < 2000 && !started_2; ++ms) std::this_thread::sleep_for(std::chrono::milliseconds(1));
          build_2_ran_during_commit_0 = started_2;
        }
        committing = false;
      });
  EXPECT_EQ(overlapping_commits, 0);
  EXPECT_TRUE(build_2_ran_during_commit_0 || !two_threads) << "build 2 waited for commit 0";

  // The builds waiting for room in the window are let go, none starts after, and the commit's
  // exception comes out (a loop that hangs ends the test binary with its message).
  for (const int64_t window : {1, 2, 4}) {
    std::vector<int64_t> order;
    std::atomic<bool> thrown{false};
    std::atomic<int64_t> started_after{0};
    auto run = std::async(std::launch::async, [&] {
      try {
        parallel_in_order_committed(
            0, 200, window,
            [&](int64_t) {
              if (thrown) ++started_after;
              std::this_thread::sleep_for(std::chrono::microseconds(200));
            },
            [&](int64_t i) {
              if (i == 20) {
                thrown = true;
                throw std::runtime_error("commit 20");
              }
              order.push_back(i);
            });
        return std::string("no exception");
      } catch (const std::runtime_error& e) {
        return std::string(e.what());
      }
    });
    if (run.wait_for(std::chrono::seconds(60)) != std::future_status::ready) {
      std::fprintf(stderr, "the loop hangs after a failed commit (window %lld)\n", static_cast<long long>(window));
      std::_Exit(1);
    }
    EXPECT_EQ(run.get(), "commit 20") << "window " << window;
    EXPECT_EQ(order.size(), 20u) << "window " << window << ": nothing committed after the failed commit";
    // Builds already let into the window may start between the throw and the loop's noting it.
    EXPECT_LE(started_after, window - 1) << "window " << window << ": builds went on after the failed commit";
  }
}

Mesh extract_with_threads(const Volume& v, const ExtractOptions& o, size_t threads) {
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
  return extract(MultiresVolume::build(v), o);
}

// A pool kept from one run for the next keeps the first objects given back whose sizes fit in the
// bytes it may keep, and lets the rest go.
TEST(LendingPoolTest, KeepsTheFirstObjectsThatFitTheBytesItMayKeep) {
  LendingPool<size_t> pool;
  for (size_t bytes : {10, 20, 30, 5}) pool.give(std::make_unique<size_t>(bytes));
  EXPECT_EQ(pool.keep_at_most(35, [](size_t b) { return b; }), 30u) << "10 and 20; 30 is past the bound";
  std::vector<size_t> taken;
  for (int i = 0; i < 3; ++i)
    if (auto t = pool.take([] { return std::unique_ptr<size_t>(); })) taken.push_back(*t);
  EXPECT_EQ(taken, (std::vector<size_t>{20, 10}));
  pool.give(std::make_unique<size_t>(40));
  EXPECT_EQ(pool.keep_at_most(35, [](size_t b) { return b; }), 0u);
  EXPECT_EQ(pool.take([] { return std::unique_ptr<size_t>(); }), nullptr);
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
