// The triangle budget's search (choose_cut_for_budget) against the walk it replaced: the
// cut moved down one group of equal keys at a time through a max-heap, the running triangle count
// of the front checked after each group (docs/METHOD.md, "Focus and triangle budget"). That walk
// is kept here as the reference, its groups cut by tie class within a key (SplitRule::refines) as
// the search's steps are. The passes that count every cut at once must choose the same eps and
// tie classes, report the same triangles, the same next finer step and its triangles, the same number of steps,
// and throw the same message below the coarsest mesh, on one thread and on several; for keys that
// take few values (a quantized store: halves of a code), for keys that take many (float data, a
// focus), for the choice of delta (simplify), on a clipped lattice and on a 2^k + 1 one, in memory
// and paged. TriangleBudgetParallel, a small version, also runs under ThreadSanitizer
// (the test script's TSan run).
#include "engine/extract/triangle_budget.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <atomic>
#include <cmath>
#include <cstdint>
#include <limits>
#include <optional>
#include <queue>
#include <stdexcept>
#include <string>
#include <vector>

#include "engine/extract/extract_drivers.h"
#include "engine/extract/options.h"
#include "engine/extract/traversal.h"
#include "engine/hierarchy/hierarchy.h"
#include "engine/synthetic/fields.h"
#include "io/store/brick_cache.h"
#include "io/store/paged_volume.h"
#include "io/store/store_format.h"
#include "io/store/store_reader.h"
#include "tests/support/temp_dir_test.h"
#include "tests/support/test_support.h"

namespace isotope {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// The reference: the front of the cut in a max-heap by key (and, with `ties`, by tie class, coarse
// first), split one group of equal keys (and classes) at a time from +infinity down, stopping at
// the first group whose mesh exceeds the budget.
template <TraversalSource Source, class Key>
BudgetChoice walk_the_cut(const Source& source, const traversal::SplitRule& rule, int64_t max_triangles, bool ties,
                          const Key& judge) {
  using namespace traversal;
  struct Item {
    double key;
    int tie;
    PackedTet tet;
    int level;
    bool positive;
    int triangles;
    bool operator<(const Item& o) const { return key != o.key ? key < o.key : tie > o.tie; }
  };
  Traversal<Source> walk(source, rule);
  std::priority_queue<Item> front;
  int64_t count = 0;
  auto add = [&](const PackedTet& t, int level, bool positive) {
    double key = 0;
    const auto fate = judge(walk, t, level, &key);
    if (fate == Traversal<Source>::Fate::culled) return;
    const int tris = walk.triangles(t, level, positive);
    count += tris;
    const int tie = ties ? SplitRule::tie_class((t[0] + t[1]) >> 1, level) : 0;
    if (fate == Traversal<Source>::Fate::split_key && key > -kInf) front.push({key, tie, t, level, positive, tris});
  };
  // Every item of this key and class (at +infinity: of this key).
  auto split_group = [&](double key, int tie) {
    while (!front.empty() && front.top().key == key && (key == kInf || front.top().tie == tie)) {
      const Item it = front.top();
      front.pop();
      count -= it.triangles;
      for (const Child& c : bisect(it.tet, it.level, it.positive)) add(c.tet, it.level + 1, c.positive);
    }
  };
  for (const Child& r : walk.roots()) add(r.tet, 0, r.positive);
  split_group(kInf, 0);
  if (count > max_triangles) throw std::runtime_error("below the coarsest: " + std::to_string(count));
  BudgetChoice choice;
  choice.triangles = count;
  choice.eps = front.empty() ? 0 : std::nextafter(front.top().key, kInf);
  while (!front.empty()) {
    const double key = front.top().key;
    const int tie = front.top().tie;
    split_group(key, tie);
    ++choice.steps;
    // Classes of this key still to split: the cut is "key > eps, or key = eps and class <= tie".
    const int ties_after = !front.empty() && front.top().key == key ? tie + 1 : -1;
    if (count > max_triangles) {
      choice.next_eps = key, choice.next_ties = ties_after, choice.next_triangles = count;
      return choice;
    }
    choice.eps = key, choice.ties = ties_after, choice.triangles = count;
  }
  choice.eps = 0;
  return choice;
}

template <TraversalSource Source>
BudgetChoice reference_eps(const Source& source, const traversal::SplitRule& rule, int64_t max_triangles) {
  return walk_the_cut(source, rule, max_triangles, true,
                      [](traversal::Traversal<Source>& walk, const traversal::PackedTet& t, int level, double* key) {
                        return walk.judge(t, level, key);
                      });
}

template <TraversalSource Source>
BudgetChoice reference_delta(const Source& source, const traversal::SplitRule& rule, int64_t max_triangles) {
  using Walk = traversal::Traversal<Source>;
  return walk_the_cut(source, rule, max_triangles, false,
                      [](Walk& walk, const traversal::PackedTet& t, int level, double* key) {
                        double error_key = 0;
                        const auto fate = walk.judge_topology(t, level, &error_key, key);
                        if (fate == Walk::Fate::split_key && std::isinf(error_key)) *key = kInf;
                        return fate;
                      });
}

// The search or the reference, or the triangles of the coarsest mesh when it throws.
struct Outcome {
  std::optional<BudgetChoice> choice;
  int64_t coarsest = -1;
};
template <class F>
Outcome run(const F& f) {
  Outcome o;
  try {
    o.choice = f();
  } catch (const std::runtime_error& e) {
    // Both say how many triangles the coarsest mesh has: compare that number.
    const std::string m = e.what();
    const size_t at = m.find_first_of("0123456789", m.find('(') == std::string::npos ? m.find(':') : m.find('('));
    o.coarsest = std::stoll(m.substr(at));
  }
  return o;
}

class TriangleBudget : public testing::TempDirTest {
 protected:
  // Compares the search with the reference on `source` over budgets from below the coarsest mesh
  // to above the full one (`steps` between), at each of `threads`; returns the budgets compared.
  template <TraversalSource Source>
  int compare(const std::string& name, const Source& source, ExtractOptions o, bool delta, int steps = 12,
              std::vector<int> thread_counts = {1, 2}) {
    const double offset = source.value_offset(), scale = source.value_scale();
    o.iso = static_cast<float>((static_cast<double>(o.iso) - offset) / scale);  // codes, as the extraction does
    const traversal::SplitRule rule(o, source.lattice(), source.origin(), source.spacing(), source.error_fold());
    auto reference = [&](int64_t b) {
      return delta ? reference_delta(source, rule, b) : reference_eps(source, rule, b);
    };
    auto search = [&](int64_t b) {
      return delta ? choose_delta_for_budget(source, rule, b) : choose_eps_for_budget(source, rule, b);
    };
    const BudgetChoice full = reference(std::numeric_limits<int64_t>::max());
    const Outcome floor = run([&] { return reference(1); });
    const int64_t coarsest = floor.choice ? 1 : floor.coarsest;
    EXPECT_GT(full.steps, 3) << name;
    std::vector<int64_t> budgets = {coarsest, coarsest + 1, full.triangles, full.triangles - 1, full.triangles + 1};
    if (coarsest > 1) budgets.push_back(coarsest - 1);
    for (int i = 1; i < steps; ++i) budgets.push_back(coarsest + (full.triangles - coarsest) * i * i / (steps * steps));
    int compared = 0;
    for (int threads : thread_counts) {
      const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, static_cast<size_t>(threads));
      for (int64_t budget : budgets) {
        if (budget < 1) continue;
        const std::string what = name + ", budget " + std::to_string(budget) + ", " + std::to_string(threads) +
                                 " threads (full mesh " + std::to_string(full.triangles) + ", coarsest " +
                                 std::to_string(coarsest) + ")";
        const Outcome want = run([&] { return reference(budget); });
        const Outcome got = run([&] { return search(budget); });
        ++compared;
        EXPECT_EQ(got.choice.has_value(), want.choice.has_value()) << what;
        if (!want.choice || !got.choice) {
          EXPECT_EQ(got.coarsest, want.coarsest) << what;
          continue;
        }
        EXPECT_EQ(got.choice->eps, want.choice->eps) << what;
        EXPECT_EQ(got.choice->ties, want.choice->ties) << what;
        EXPECT_EQ(got.choice->triangles, want.choice->triangles) << what;
        EXPECT_EQ(got.choice->next_eps, want.choice->next_eps) << what;
        EXPECT_EQ(got.choice->next_ties, want.choice->next_ties) << what;
        EXPECT_EQ(got.choice->next_triangles, want.choice->next_triangles) << what;
        EXPECT_EQ(got.choice->steps, want.choice->steps) << what;
      }
    }
    return compared;
  }
  std::string store(const Volume& v, const std::string& name, int quantize_bits = 0) {
    ConvertOptions o;
    o.quantize_bits = quantize_bits;
    return testing::write_store(v, dir_.string(), name, o);
  }
};

using TriangleBudgetParallel = TriangleBudget;  // small enough for ThreadSanitizer

// The search's sums by key and tie class: one sum per distinct pair through growth, 0 and -0 one
// key (as they are one eps), and every sum kept.
TEST(TieKeySums, OneSumPerKeyAndClassThroughGrowth) {
  budget_detail::TieKeySums sums;
  const double inf = std::numeric_limits<double>::infinity();
  for (int round = 0; round < 3; ++round)
    for (int k = 0; k < 1000; ++k)
      for (int tie = 0; tie < 3; ++tie) sums[{k == 0 ? (round == 1 ? -0.0 : 0.0) : k * 0.5, tie}] += k + tie;
  sums[{inf, 0}] += 7;
  sums[{inf, 0}] += 1;
  EXPECT_EQ(sums.size(), 3001u);
  int64_t visited = 0;
  sums.for_each([&](const budget_detail::TieKey& key, int64_t sum) {
    ++visited;
    if (std::isinf(key.key)) {
      EXPECT_EQ(sum, 8);
    } else {
      EXPECT_EQ(sum, 3 * (static_cast<int64_t>(key.key * 2) + key.tie)) << key.key << " " << key.tie;
    }
  });
  EXPECT_EQ(visited, 3001);
  sums.clear();
  EXPECT_EQ(sums.size(), 0u);
  sums[{1.0, 0}] += 2;
  EXPECT_EQ(sums.size(), 1u);
}

TEST_F(TriangleBudget, CountsEveryCutAsTheWalkDownTheCutDoesInMemory) {
  int compared = 0;
  // A clipped lattice (45 x 50 x 39 in 64^3): what reaches past the box is clipped, and counted so.
  const Volume noise = testing::crop(generate_noise(50, 17), {45, 50, 39});
  const Hierarchy noise_h = Hierarchy::build(noise);
  for (TopologyMode mode : {TopologyMode::none, TopologyMode::preserve}) {
    ExtractOptions o;
    o.iso = 0.05f, o.topology = mode;
    compared += compare("noise " + std::string(to_string(mode)), noise_h, o, false);
  }
  {  // a focus: keys err / g take as many values as there are diamonds near the point
    ExtractOptions o;
    o.iso = 0.05f, o.focus = Focus{{0.2, -0.1, 0.3}, 0.5};
    compared += compare("noise with a focus", noise_h, o, false);
  }
  {  // the choice of delta: weights as keys
    ExtractOptions o;
    o.iso = 0.05f, o.topology = TopologyMode::simplify, o.weight = SimplificationWeight::size;
    compared += compare("noise, delta", noise_h, o, true);
  }
  // 2^k + 1: nothing leaves the data box, the coarsest mesh is the roots'.
  const Hierarchy sphere = Hierarchy::build(generate_sphere(33));
  ExtractOptions o;
  o.iso = 0.0f;
  compared += compare("sphere 33", sphere, o, false);
  EXPECT_GT(compared, 2 * 5 * 16);
}

TEST_F(TriangleBudget, CountsEveryCutAsTheWalkDownTheCutDoesPaged) {
  int compared = 0;
  struct Case {
    std::string name;
    Volume volume;
    float iso;
    int quantize_bits;
  };
  const Case cases[] = {
      {"neghip", testing::load_shared(testing::shared_volumes()[1]), 32.5f, 0},
      {"hydrogen q8", testing::load_shared(testing::shared_volumes()[2]), 0.05f, 8},  // keys: halves of a code
  };
  for (const Case& c : cases) {
    const StoreReader reader(store(c.volume, "budget", c.quantize_bits));
    BrickCache cache(reader, uint64_t{1} << 30);
    const PagedVolume paged(cache);
    for (TopologyMode mode : {TopologyMode::none, TopologyMode::preserve}) {
      ExtractOptions o;
      o.iso = c.iso, o.topology = mode;
      compared += compare(c.name + " " + std::string(to_string(mode)), paged, o, false);
    }
  }
  EXPECT_GT(compared, 4 * 2 * 16);
}

// A request superseded in the server (or interrupted on the command line) stops the search too.
TEST_F(TriangleBudget, ACancelledSearchStops) {
  const Hierarchy sphere = Hierarchy::build(generate_sphere(65));
  const std::atomic<bool> cancel{true};
  ExtractCall o;
  o.iso = 0, o.cancel = &cancel;
  const traversal::SplitRule rule(o, sphere.lattice(), sphere.origin(), sphere.spacing(), sphere.error_fold());
  EXPECT_THROW(choose_eps_for_budget(sphere, rule, 1000), ExtractionCancelled);
  o.topology = TopologyMode::simplify;
  const traversal::SplitRule simplify(o, sphere.lattice(), sphere.origin(), sphere.spacing(), sphere.error_fold());
  EXPECT_THROW(choose_delta_for_budget(sphere, simplify, 1000), ExtractionCancelled);
}

// Threads share the source and the frontier; each sums into a table of its own.
TEST_F(TriangleBudgetParallel, SameChoiceOnAnyThreadCount) {
  const Volume noise = testing::crop(generate_noise(33, 5), {31, 33, 27});
  const Hierarchy memory = Hierarchy::build(noise);
  ExtractOptions o;
  o.iso = 0.05f;
  int compared = compare("small noise", memory, o, false, 4, {1, 2, 4});
  const StoreReader reader(store(noise, "small"));
  BrickCache cache(reader, 1);  // the smallest cache: threads evict each other's bricks
  const PagedVolume paged(cache);
  compared += compare("small noise paged", paged, o, false, 4, {2, 4});
  EXPECT_GT(compared, 5 * 5);
}

// A budget's cut is reported in the data's units (chosen_eps = key x scale) and typed back to get
// its mesh again; on a quantized store the key must come back exactly, or the cut is lost (key
// >= eps no longer holds, or its tie classes, which need key == eps, no longer apply). Keys as a
// store makes them: a float error in codes plus the quantization's half code; scales as convert
// makes them, (hi - lo) / (2^bits - 1), and their squares for the weights of delta.
TEST(QuantizedThreshold, AKeyReportedInTheDatasUnitsComesBackExactly) {
  uint64_t state = 12345;
  auto next_unit = [&state] {  // in [0, 1)
    state = state * 6364136223846793005ull + 1442695040888963407ull;
    return static_cast<double>(state >> 11) / 9007199254740992.0;
  };
  int checked = 0, plain_quotient_misses = 0;
  for (int s = 0; s < 200; ++s) {
    const auto lo = static_cast<float>(-1000 * next_unit());
    const auto hi = static_cast<float>(lo + 1e-3 + 5000 * next_unit() * next_unit());
    const int bits = s % 2 == 0 ? 8 : 16;
    const double scale = (static_cast<double>(hi) - lo) / static_cast<double>((1 << bits) - 1);
    for (const double factor : {scale, scale * scale}) {
      for (int k = 0; k < 200; ++k) {
        const auto error =
            static_cast<float>(k % 2 == 0 ? std::ldexp(std::floor(next_unit() * 4096), -4) : 300 * next_unit());
        const double key = static_cast<double>(error) + static_cast<double>(kQuantizationError);
        const double reported = threshold_in_data(key, factor);
        ASSERT_EQ(threshold_in_codes(reported, factor), key)
            << "key " << key << " factor " << factor << " reported " << reported;
        plain_quotient_misses += reported / factor != key;
        ++checked;
      }
    }
  }
  EXPECT_EQ(checked, 80000);
  // What the plain quotient gets wrong, so that this test covers the case it is about.
  EXPECT_GT(plain_quotient_misses, checked / 50) << plain_quotient_misses << " of " << checked;
  RecordProperty("plain quotient misses", std::to_string(plain_quotient_misses) + " of " + std::to_string(checked));
  // Keys of arbitrary low bits (a focus divides the error by its factor) come back as the plain
  // quotient brings them: never worse.
  int arbitrary = 0, arbitrary_exact = 0;
  for (int k = 0; k < 20000; ++k) {
    const double factor = 0.001 + 20 * next_unit();
    const double key = (1 + 300 * next_unit()) / (0.05 + next_unit());
    const double reported = threshold_in_data(key, factor);
    if (reported / factor == key) {
      ASSERT_EQ(threshold_in_codes(reported, factor), key) << "key " << key << " factor " << factor;
      ++arbitrary_exact;
    }
    ++arbitrary;
  }
  EXPECT_GT(arbitrary_exact, arbitrary / 2);
  // 0 and infinity stay; a factor of 1 changes nothing.
  EXPECT_EQ(threshold_in_codes(0.0, 0.37), 0.0);
  EXPECT_EQ(threshold_in_codes(std::numeric_limits<double>::infinity(), 0.37), std::numeric_limits<double>::infinity());
  EXPECT_EQ(threshold_in_codes(3.0, 1.0), 3.0);
}

}  // namespace
}  // namespace isotope
