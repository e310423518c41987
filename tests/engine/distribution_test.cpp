// A distributed extraction and conversion (isotope/distribution.h) with the ranks as
// threads of this process, so that the engine's side of it runs under the sanitizers (the test
// script's ASan and TSan runs) without MPI: the same mesh and the same store, byte for byte, as one process; a
// failure on one rank thrown on every rank with its message; nothing left behind. The MPI face
// itself is tested through mpirun by the MPI tests.
#include "isotope/distribution.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <condition_variable>
#include <exception>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "engine/extract/adaptive_extract.h"
#include "engine/extract/budget_memo.h"
#include "engine/extract/streamed_extract.h"
#include "engine/hierarchy/hierarchy.h"
#include "engine/synthetic/fields.h"
#include "isotope/convert.h"
#include "isotope/error.h"
#include "isotope/extract.h"
#include "isotope/source.h"
#include "tbb/global_control.h"
#include "tests/support/byte_files.h"
#include "tests/support/temp_dir_test.h"
#include "tests/support/test_support.h"

namespace isotope {
namespace {

// The ranks' meeting point: each exchange waits for all of them, then hands every one the lot.
class ThreadGroup {
 public:
  explicit ThreadGroup(int ranks) : ranks_(ranks), slots_(static_cast<size_t>(ranks)) {}
  int ranks() const { return ranks_; }
  std::vector<std::vector<uint8_t>> exchange(int rank, const std::vector<uint8_t>& mine) {
    std::unique_lock<std::mutex> lock(mutex_);
    slots_[static_cast<size_t>(rank)] = mine;
    const uint64_t generation = generation_;
    if (++arrived_ == ranks_) {
      arrived_ = 0;
      result_ = slots_;
      ++generation_;
      done_.notify_all();
    } else {
      done_.wait(lock, [&] { return generation_ != generation; });
    }
    return result_;  // replaced only when every rank, this one included, has come back
  }

 private:
  int ranks_;
  std::mutex mutex_;
  std::condition_variable done_;
  int arrived_ = 0;
  uint64_t generation_ = 0;
  std::vector<std::vector<uint8_t>> slots_, result_;
};

class ThreadRank : public Distribution {
 public:
  ThreadRank(ThreadGroup& group, int rank) : group_(group), rank_(rank) {}
  int rank() const override { return rank_; }
  int ranks() const override { return group_.ranks(); }
  std::vector<std::vector<uint8_t>> all_gather(const std::vector<uint8_t>& mine) const override {
    return group_.exchange(rank_, mine);
  }
  std::vector<std::vector<uint8_t>> gather(const std::vector<uint8_t>& mine) const override {
    auto all = group_.exchange(rank_, mine);
    if (rank_ != 0) return {};
    return all;
  }

 private:
  ThreadGroup& group_;
  int rank_;
};

// Runs work(rank) on `ranks` threads; what each returned, or threw.
template <class T>
struct Outcome {
  std::optional<T> value;
  std::exception_ptr error;
};
template <class T>
std::vector<Outcome<T>> on_ranks(int ranks, const std::function<T(const Distribution&)>& work) {
  ThreadGroup group(ranks);
  std::vector<Outcome<T>> out(static_cast<size_t>(ranks));
  std::vector<std::thread> threads;
  for (int r = 0; r < ranks; ++r)
    threads.emplace_back([&, r] {
      const ThreadRank me(group, r);
      try {
        out[static_cast<size_t>(r)].value = work(me);
      } catch (...) {
        out[static_cast<size_t>(r)].error = std::current_exception();
      }
    });
  for (std::thread& t : threads) t.join();
  return out;
}

// Every rank threw DistributedError with this message.
template <class T>
void expect_every_rank_threw(const std::vector<Outcome<T>>& out, const char* message, bool usage = false) {
  for (const auto& o : out) {
    ASSERT_TRUE(o.error);
    try {
      std::rethrow_exception(o.error);
    } catch (const DistributedError& e) {
      EXPECT_STREQ(e.what(), message);
      EXPECT_EQ(e.usage_error, usage);
    } catch (const std::exception& e) {
      ADD_FAILURE() << "not a DistributedError: " << e.what();
    }
  }
}

std::string bytes_of(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), {}};
}

void expect_same(const Mesh& a, const Mesh& b) {
  ASSERT_EQ(a.positions.size(), b.positions.size());
  ASSERT_EQ(a.triangles.size(), b.triangles.size());
  EXPECT_TRUE(a.positions == b.positions);
  EXPECT_TRUE(a.triangles == b.triangles);
}

TEST(ShareByCost, ContiguousSharesOfEqualCost) {
  EXPECT_EQ(share_by_cost({1, 1, 1, 1}, 2), (std::vector<size_t>{0, 2, 4}));
  EXPECT_EQ(share_by_cost({1, 1, 1, 1, 1, 1}, 3), (std::vector<size_t>{0, 2, 4, 6}));
  EXPECT_EQ(share_by_cost({10, 1, 1, 1, 1}, 2), (std::vector<size_t>{0, 1, 5}));  // the heavy one alone
  EXPECT_EQ(share_by_cost({1, 1, 1, 1, 10}, 2), (std::vector<size_t>{0, 4, 5}));
  // More ranks than items, or nothing to do: bounds still rise from 0 to the end.
  for (const auto& costs : {std::vector<double>{5}, std::vector<double>{0, 0, 0}, std::vector<double>{}}) {
    const std::vector<size_t> b = share_by_cost(costs, 4);
    ASSERT_EQ(b.size(), 5u);
    EXPECT_EQ(b.front(), 0u);
    EXPECT_EQ(b.back(), costs.size());
    EXPECT_TRUE(std::is_sorted(b.begin(), b.end()));
  }
}

TEST(SettleTogether, OneRanksFailureIsEveryRanksWithItsMessage) {
  const auto out = on_ranks<int>(3, [](const Distribution& g) {
    settle_together(g, [&] {
      if (g.rank() == 1) throw IoError("scan.isotope: brick 7: checksum mismatch");
    });
    return 0;
  });
  expect_every_rank_threw(out, "rank 1 of 3: scan.isotope: brick 7: checksum mismatch");
}

TEST(SettleTogether, WhatEveryRankMetIsSaidAsOneProcessSaysItAndUsageStaysUsage) {
  const auto all = on_ranks<int>(2, [](const Distribution& g) {
    settle_together(g, [] { throw OptionError("eps", "must be >= 0, got '-1'"); });
    return 0;
  });
  expect_every_rank_threw(all, "--eps: must be >= 0, got '-1'", true);
  const auto none = on_ranks<int>(3, [](const Distribution& g) {
    settle_together(g, [] {});
    return 7;
  });
  for (const auto& o : none) EXPECT_EQ(o.value, 7);
}

ExtractOptions options_for(double eps, int64_t budget = 0) {
  ExtractOptions o;
  o.iso = 0.1f;
  o.eps = eps;
  o.max_triangles = budget;
  return o;
}

// The in-memory paths: eps 0 marches slabs (no records: every slab costs the same), eps > 0 and
// a budget share the traversal's pieces.
TEST(DistributedExtract, ThreeRanksGiveTheSingleProcessMeshOnRankZero) {
  const Volume volume = generate_noise(61, 3);  // 61: the lattice (65) is clipped to the data
  for (const ExtractOptions& o : {options_for(0), options_for(0.02), options_for(0, 20000)}) {
    ExtractStats alone;
    const Mesh single = extract(volume, o, {}, &alone);
    ASSERT_GT(single.triangles.size(), 1000u);
    ASSERT_GT(alone.tets_emitted, 0);
    const auto out = on_ranks<std::pair<Mesh, ExtractStats>>(3, [&](const Distribution& g) {
      RunContext run;
      run.distribution = &g;
      ExtractStats stats;
      Mesh mesh = extract(volume, o, run, &stats);
      return std::pair{std::move(mesh), stats};
    });
    for (int r = 0; r < 3; ++r) {
      ASSERT_FALSE(out[static_cast<size_t>(r)].error) << "rank " << r;
      const auto& [mesh, stats] = *out[static_cast<size_t>(r)].value;
      EXPECT_EQ(stats.ranks.size(), 3u);
      // Rank 0 reports the counts of all, as the single process counts them (at eps 0 every rank
      // does; above it, a rank other than 0 counts what it kept).
      if (r == 0 || (o.eps == 0 && o.max_triangles == 0)) {
        EXPECT_EQ(stats.tets_visited, alone.tets_visited) << "rank " << r << ", eps " << o.eps;
        EXPECT_EQ(stats.tets_emitted, alone.tets_emitted) << "rank " << r << ", eps " << o.eps;
      }
      if (r == 0)
        expect_same(mesh, single);
      else
        EXPECT_TRUE(mesh.triangles.empty() && mesh.positions.empty());
    }
  }
}

// A budget from a sample (docs/METHOD.md, "Focus and triangle budget"): every rank counts the guess's whole
// mesh, so all of them stand by it or all fall back to the exact choice, as one process does, and
// rank 0 has that process's mesh. Both outcomes are met: a sample of level 9 stands, one of 12 of
// the 96 subtrees of level 4 does not.
TEST(DistributedExtract, ASampledBudgetStandsOrFallsBackOnEveryRankAlike) {
  const Hierarchy hierarchy = Hierarchy::build(generate_noise(61, 3));
  int stood = 0, fell_back = 0;
  for (const BudgetSample sample : {BudgetSample{9, 3}, BudgetSample{4, 3}}) {
    for (const int64_t budget : {int64_t{20000}, int64_t{40000}}) {
      const ExtractOptions o = options_for(0, budget);
      ExtractStats single_stats;
      const Mesh single = extract_adaptive(hierarchy, o, &single_stats, sample);
      ++(single_stats.budget_sampled ? stood : fell_back);
      // Each rank with a memo that holds a wrong choice for these options: a distributed
      // extraction neither looks there (every rank must search alike) nor remembers.
      std::array<BudgetMemo, 3> memos;
      for (BudgetMemo& memo : memos) memo.remember(o, sample, BudgetMemo::Choice{1e30, -1, 0, {}});
      const auto out = on_ranks<std::pair<Mesh, ExtractStats>>(3, [&](const Distribution& g) {
        ExtractCall mine = o;
        mine.distribution = &g;
        ExtractStats stats;
        Mesh mesh = extract_adaptive(hierarchy, mine, &stats, sample, &memos[static_cast<size_t>(g.rank())]);
        return std::pair{std::move(mesh), stats};
      });
      for (const BudgetMemo& memo : memos) EXPECT_EQ(memo.size(), 1u);
      for (int r = 0; r < 3; ++r) {
        ASSERT_FALSE(out[static_cast<size_t>(r)].error) << "rank " << r;
        const auto& [mesh, stats] = *out[static_cast<size_t>(r)].value;
        EXPECT_EQ(stats.budget_sampled, single_stats.budget_sampled) << "rank " << r << " budget " << budget;
        EXPECT_FALSE(stats.budget_remembered) << "rank " << r << " budget " << budget;
        EXPECT_EQ(stats.chosen_eps, single_stats.chosen_eps) << "rank " << r << " budget " << budget;
        EXPECT_EQ(stats.chosen_eps_ties, single_stats.chosen_eps_ties) << "rank " << r << " budget " << budget;
        if (r == 0) expect_same(mesh, single);
      }
    }
  }
  EXPECT_GT(stood, 0);
  EXPECT_GT(fell_back, 0);
}

// eps 0 streamed from a file (docs/METHOD.md, "eps = 0 from a file"): each rank reads the layers of its
// own share of the slabs only, in order, a window at a time, and rank 0 has the single process's
// mesh. Layers of 1 MB: a window is one layer of blocks, so each of the 2 ranks' 2 slabs is a
// window of its own. A failed read on one rank stops every rank with its message.
TEST(DistributedExtract, EpsZeroStreamedReadsEachRanksShareOnly) {
  // A ball of radius 12 about (260, 260, 16): in every slab, and few blocks to march.
  const Volume volume = testing::make_volume({520, 520, 33}, [](int64_t x, int64_t y, int64_t z) {
    return 12 - std::hypot(static_cast<double>(x - 260), static_cast<double>(y - 260), static_cast<double>(z - 16));
  });
  ASSERT_EQ(streamed_window_bytes(volume.dims), 520 * 520 * 9 * 4);
  const ExtractOptions o = options_for(0);
  ExtractStats alone;
  const Mesh single = extract(volume, o, {}, &alone);
  ASSERT_GT(single.triangles.size(), 1000u);
  std::array<std::vector<std::array<int64_t, 2>>, 2> reads;  // per rank: (first layer, layers) per call
  const auto source_for = [&](int rank, int64_t unreadable) {
    return LayerSource{volume.dims, volume.spacing, volume.origin,
                       [&, rank, unreadable](int64_t z, int64_t n, float* out) {
                         if (z <= unreadable && unreadable < z + n) throw IoError("layer 30 unreadable");
                         reads[static_cast<size_t>(rank)].push_back({z, n});
                         std::copy(volume.data() + volume.index(0, 0, z), volume.data() + volume.index(0, 0, z + n),
                                   out);
                       },
                       nullptr};
  };
  const auto out = on_ranks<std::pair<Mesh, ExtractStats>>(2, [&](const Distribution& g) {
    ExtractCall mine = o;
    mine.distribution = &g;
    ExtractStats stats;
    Mesh mesh = extract_streamed(source_for(g.rank(), -1), mine, &stats);
    return std::pair{std::move(mesh), stats};
  });
  for (int r = 0; r < 2; ++r) {
    ASSERT_FALSE(out[static_cast<size_t>(r)].error) << "rank " << r;
    const auto& [mesh, stats] = *out[static_cast<size_t>(r)].value;
    ASSERT_EQ(stats.ranks.size(), 2u);
    EXPECT_EQ(stats.ranks[static_cast<size_t>(r)].items, 2) << "rank " << r;
    EXPECT_EQ(stats.tets_visited, alone.tets_visited) << "rank " << r;
    EXPECT_EQ(stats.tets_emitted, alone.tets_emitted) << "rank " << r;
    if (r == 0)
      expect_same(mesh, single);
    else
      EXPECT_TRUE(mesh.triangles.empty() && mesh.positions.empty());
  }
  // Rank 0's slabs hold cell layers 0..15, rank 1's 16..31: each reads its own node layers, a
  // window of 9 at a time, the top one again as the next window's first.
  using Reads = std::vector<std::array<int64_t, 2>>;
  EXPECT_EQ(reads[0], (Reads{{0, 9}, {8, 9}}));
  EXPECT_EQ(reads[1], (Reads{{16, 9}, {24, 9}}));
  const auto failed = on_ranks<int>(2, [&](const Distribution& g) {
    ExtractCall mine = o;
    mine.distribution = &g;
    extract_streamed(source_for(g.rank(), 30), mine);
    return 0;
  });
  expect_every_rank_threw(failed, "rank 1 of 2: layer 30 unreadable");
}

// The same on 3 ranks where a window could hold the whole volume: each rank reads its share in one
// window, the last slab 5 cell layers thin, and with keep_shares each rank keeps
// the mesh of its share that a volume in memory gives it: the same shares. On more ranks than slabs
// a rank with no share reads nothing.
TEST(DistributedExtract, EpsZeroStreamedSharesAreTheInMemoryOnes) {
  const Volume volume = testing::make_volume({100, 90, 70}, [](int64_t x, int64_t y, int64_t z) {
    return 20 - std::hypot(static_cast<double>(x - 50), static_cast<double>(y - 45), static_cast<double>(z - 34));
  });
  const ExtractOptions o = options_for(0);
  for (const int ranks : {3, 12}) {
    std::vector<std::vector<std::array<int64_t, 2>>> reads(static_cast<size_t>(ranks));
    const auto out = on_ranks<std::pair<Mesh, Mesh>>(ranks, [&](const Distribution& g) {
      RunContext run;
      run.distribution = &g;
      run.keep_shares = true;
      const ExtractCall mine(o, run);
      const LayerSource source{volume.dims, volume.spacing, volume.origin,
                               [&](int64_t z, int64_t n, float* to) {
                                 reads[static_cast<size_t>(g.rank())].push_back({z, n});
                                 std::copy(volume.data() + volume.index(0, 0, z),
                                           volume.data() + volume.index(0, 0, z + n), to);
                               },
                               nullptr};
      Mesh streamed = extract_streamed(source, mine);
      return std::pair{std::move(streamed), extract(volume, o, run)};
    });
    for (int r = 0; r < ranks; ++r) {
      ASSERT_FALSE(out[static_cast<size_t>(r)].error) << ranks << " ranks, rank " << r;
      const auto& [streamed, in_memory] = *out[static_cast<size_t>(r)].value;
      expect_same(streamed, in_memory);
    }
    using Reads = std::vector<std::array<int64_t, 2>>;
    if (ranks == 3) {  // 9 slabs, the last 5 cell layers thin: 3 a rank, each one window
      EXPECT_EQ(reads[0], (Reads{{0, 25}}));
      EXPECT_EQ(reads[1], (Reads{{24, 25}}));
      EXPECT_EQ(reads[2], (Reads{{48, 22}}));
    } else {
      int64_t next = 0, idle = 0;
      for (const Reads& rank_reads : reads) {
        idle += rank_reads.empty();
        for (const auto& [z, n] : rank_reads) {
          EXPECT_EQ(z, next);
          next = z + n - 1;
        }
      }
      EXPECT_EQ(next, 69) << "every layer read, once, in rank order";
      EXPECT_EQ(idle, 3) << "9 slabs on 12 ranks";
    }
  }
}

// A fresh folder per test (TempDirTest): what a failed convert must leave empty.
class DistributedStore : public testing::TempDirTest {};

TEST_F(DistributedStore, FourRanksWriteTheSingleProcessFileAndExtractFromIt) {
  const Volume volume = generate_noise(75, 5);
  ConvertOptions single_options;
  single_options.brick_bits = 3;  // many bricks and tiles for a small volume
  convert(volume, (dir_ / "one.isotope").string(), single_options);
  const auto out = on_ranks<int>(4, [&](const Distribution& g) {
    RunContext run;
    run.distribution = &g;
    convert(volume, (dir_ / "four.isotope").string(), single_options, run);
    return 0;
  });
  for (const auto& o : out) ASSERT_FALSE(o.error);
  EXPECT_TRUE(bytes_of(dir_ / "four.isotope") == bytes_of(dir_ / "one.isotope")) << "another file";
  EXPECT_EQ(entries(), (std::vector<std::string>{"four.isotope", "one.isotope"}));  // no hand-over left

  // The paged paths: the slabs' and the pieces' costs from the store's records.
  VolumeSpec spec;
  spec.path = (dir_ / "one.isotope").string();
  const Source store = open_volume(spec);
  for (const ExtractOptions& opt : {options_for(0), options_for(0.01)}) {
    const Mesh single = store.extract(opt);
    const auto meshes = on_ranks<Mesh>(4, [&](const Distribution& g) {
      RunContext run;
      run.distribution = &g;
      return store.extract(opt, run);
    });
    ASSERT_FALSE(meshes[0].error);
    expect_same(*meshes[0].value, single);
  }
}

// Under mpirun every hand-over is a shared file, so the ranks build two bands a pass where the
// tiles allow (64 nodes a side, an even number of bricks): each rank builds band j+1's tiles
// beside its own run of band j's, and the bricks of band j+1, which come out of the tiles'
// order at the grid's far faces (191 nodes: band 1's last brick row comes with band 0's last
// tiles), are each placed where one process puts them.
TEST_F(DistributedStore, RanksThatBuildTwoBandsAPassWriteTheSingleProcessFile) {
  // The tiles' size follows the threads (64 nodes where band 0 has 4 a thread): two threads, so
  // that band 0's 2 x 2 x 3 such tiles take it on any machine.
  const tbb::global_control two(tbb::global_control::max_allowed_parallelism, 2);
  const Volume volume = testing::crop(generate_noise(200, 5), {100, 90, 191});
  ConvertOptions single_options;
  single_options.memory_mb = 256;  // room for two fused tiles of 64 nodes in flight
  convert(volume, (dir_ / "one.isotope").string(), single_options);
  for (const int ranks : {2, 3}) {
    const std::string name = std::to_string(ranks) + ".isotope";
    const auto out = on_ranks<ConvertStats>(ranks, [&](const Distribution& g) {
      RunContext run;
      run.distribution = &g;
      return convert(volume, (dir_ / name).string(), single_options, run);
    });
    for (const auto& o : out) ASSERT_FALSE(o.error);
    EXPECT_EQ(out[0].value->bands_built_beside, 4) << "bands 1, 3, 5 and 7 of 0..8 built beside the band below";
    EXPECT_TRUE(bytes_of(dir_ / name) == bytes_of(dir_ / "one.isotope")) << ranks << " ranks: another file";
  }
  EXPECT_EQ(entries(), (std::vector<std::string>{"2.isotope", "3.isotope", "one.isotope"}));  // no hand-over left
}

// A budget that the full-resolution mesh fits is that mesh, counted, with no hierarchy built; spread
// over processes it is searched instead, so a prepare under ranks builds the hierarchy, as the
// extraction it prepares would, where every rank meets a failure of it together.
TEST_F(DistributedStore, APreparedBudgetUnderRanksBuildsTheHierarchyItsSearchReads) {
  const Volume volume = generate_noise(33, 5);
  const std::string raw = (dir_ / "noise_33x33x33_float32.raw").string();
  testing::write_values(raw, volume.values);
  const ExtractOptions o = options_for(0, static_cast<int64_t>(extract(volume, options_for(0)).triangles.size()));
  const Source alone = open_volume({raw, std::nullopt, std::nullopt});
  alone.prepare({o});
  EXPECT_FALSE(alone.info().hierarchy_built) << "alone, the budget is counted";
  const auto built = on_ranks<bool>(2, [&](const Distribution& g) {
    const Source source = open_volume({raw, std::nullopt, std::nullopt});
    RunContext run;
    run.distribution = &g;
    source.prepare({o}, run);
    return source.info().hierarchy_built;
  });
  for (const auto& b : built) {
    ASSERT_FALSE(b.error);
    EXPECT_TRUE(*b.value) << "spread, the budget's hierarchy is built by the prepare";
  }
}

TEST_F(DistributedStore, ARankThatFailsStopsEveryRankAndLeavesNothing) {
  const Volume volume = generate_noise(75, 5);
  std::atomic<bool> stop{true};  // rank 2's convert is "interrupted" at its first batch of tiles
  const auto out = on_ranks<int>(3, [&](const Distribution& g) {
    ConvertOptions o;
    o.brick_bits = 3;
    RunContext run;
    run.distribution = &g;
    if (g.rank() == 2) run.cancel = &stop;
    convert(volume, (dir_ / "three.isotope").string(), o, run);
    return 0;
  });
  expect_every_rank_threw(out, "rank 2 of 3: interrupted");
  EXPECT_TRUE(entries().empty());  // no store, no temporary, no hand-over
}

}  // namespace
}  // namespace isotope
