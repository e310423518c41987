#pragma once
// Adaptive extraction over any source of values and records (engine/extract/traversal.h): the traversal
// is cut into pieces, the pieces run as parallel tasks, and their meshes are welded in order.
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <functional>
#include <memory>
#include <optional>
#include <stdexcept>
#include <vector>

#include "engine/core/lending_pool.h"
#include "engine/core/parallel.h"
#include "engine/extract/budget_memo.h"
#include "engine/extract/distributed_parts.h"
#include "engine/extract/extract_drivers.h"
#include "engine/extract/finest_extract.h"
#include "engine/extract/traversal.h"
#include "engine/extract/triangle_budget.h"
#include "engine/mesh/box_clip.h"
#include "engine/mesh/piece_weld.h"

namespace isotope {

// Deep enough for a few hundred pieces (6 roots, two children per level) to balance the threads,
// shallow enough that each is worth a task: at most kPieceLevel, and at least kPieceDepth levels
// above the finest, so that a piece of a small lattice still spans 2^15 finest tetrahedra (some
// 5,500 cells). A piece costs a few microseconds of its own (its walk, its mesh, its share of the
// weld), which on a 65^3 volume cut at level 6 was about half of a coarse extraction on two
// threads (docs/METHOD.md, "Fresh memory"). Fixed by the lattice, so the pieces and hence the
// welding order do not depend on the thread count.
constexpr int kPieceLevel = 6, kPieceDepth = 15;
inline int piece_level(const Lattice& lattice) {
  return std::clamp(lattice.max_level() - kPieceDepth, std::min(3, lattice.max_level()), kPieceLevel);
}

// The adaptive extraction at the options' eps (in the source's value units): the traversal cut
// into pieces run as parallel tasks (shared among processes with a group), their meshes welded in
// piece order into *mesh (on rank 0; on every rank with keep_shares), the counts added to *total.
// With `check`, this process's triangle count goes to it before the weld, which is skipped
// (returning false) when it says no.
template <TraversalSource Source, class Together>
bool extract_pieces(const Source& source, const ExtractOptions& options, const Together& together, ExtractStats& total,
                    Mesh* mesh, const std::function<bool(int64_t)>& check) {
  using namespace traversal;
  const Distribution* group = options.distribution;
  const SplitRule rule(options, source.lattice(), source.origin(), source.spacing(), source.error_fold());
  std::vector<Piece> pieces;
  // Spread over processes: this one runs its share of the pieces, and rank 0 welds them all
  // (engine/extract/distributed_parts.h). Every other rank returns an empty mesh.
  std::vector<size_t> shares;
  std::vector<double> costs;
  together([&] {
    {  // scoped: a paged source's reader lets its bricks go before the pieces run
      Traversal<Source> top(source, rule);
      pieces = top.split(piece_level(source.lattice()));
      total.tets_visited = top.tets_visited();
      total.tets_simplified = top.tets_simplified();
    }
  });
  shares = {0, pieces.size()};
  if (group) {
    costs = share_costs(*group, pieces.size(), [&](size_t first, size_t last, double* out) {
      piece_costs(source, rule, pieces, first, last, out);
    });
    shares = share_by_cost(costs, group->ranks());
  }
  const size_t first = shares[static_cast<size_t>(group ? group->rank() : 0)];
  const size_t last = shares[static_cast<size_t>(group ? group->rank() : 0) + 1];
  const auto work_start = std::chrono::steady_clock::now();
  double work_seconds = 0;  // this process's share of the pieces, without waiting for the others
  std::vector<PartMesh> parts(last - first);
  LendingPool<LevelScratch<Source>> levels;
  auto run_share = [&] {
    parallel_for_in_order(int64_t{0}, static_cast<int64_t>(parts.size()), [&](int64_t j) {
      const int64_t i = static_cast<int64_t>(first) + j;
      throw_if_cancelled(rule.options());
      std::unique_ptr<LevelScratch<Source>> scratch =
          levels.take([] { return std::make_unique<LevelScratch<Source>>(); });
      Traversal<Source> t(source, rule, scratch.get());
      t.keep_keys();
      t.run(pieces[static_cast<size_t>(i)]);
      PartMesh& part = parts[static_cast<size_t>(j)];
      const Piece& piece = pieces[static_cast<size_t>(i)];
      part.region = {unpack(piece.tet[0]), unpack(piece.tet[1]), unpack(piece.tet[2]), unpack(piece.tet[3])};
      part.tets_visited = t.tets_visited();
      part.tets_emitted = t.tets_emitted();
      part.tets_simplified = t.tets_simplified();
      part.keys = t.take_keys();
      part.mesh = t.take();
      levels.give(std::move(scratch));  // t no longer walks
    });
    work_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - work_start).count();
  };
  if (group) {
    RankLoad load;
    settle_together(*group, run_share);
    for (size_t i = first; i < last; ++i) load.cost += costs[i];
    for (const PartMesh& p : parts) load.work += p.tets_visited;
    load.items = static_cast<int64_t>(last - first);
    load.seconds = work_seconds;
    if constexpr (requires { source.bytes_read(); }) load.bytes_read = source.bytes_read();
    total.ranks = gather_loads(*group, load);
  } else {
    run_share();
  }
  levels.clear();  // the walks' scratch and welding tables, before the weld takes its memory
  // What reaches past the data box is clipped to it once welded (engine/mesh/box_clip.h).
  const BoxClip box = BoxClip::of(source.data_dims(), source.lattice().n, source.origin(), source.spacing());
  if (check) {
    std::vector<int64_t> counts(parts.size());
    parallel_for(int64_t{0}, static_cast<int64_t>(parts.size()), [&](int64_t i) {
      counts[static_cast<size_t>(i)] = clipped_triangles(parts[static_cast<size_t>(i)].mesh, box);
    });
    int64_t mine = 0;
    for (int64_t c : counts) mine += c;
    if (!check(mine)) return false;
  }
  if (group && !options.keep_shares) parts = gather_parts(*group, std::move(parts));  // rank 0's parts: all of them
  for (const PartMesh& p : parts) {
    total.tets_visited += p.tets_visited;
    total.tets_emitted += p.tets_emitted;
    total.tets_simplified += p.tets_simplified;
  }
  // Rank 0 (or every rank, keeping its share) welds; the others wait, so that running out of
  // memory in the weld stops them too.
  together([&] {
    if (!group || options.keep_shares || group->rank() == 0) {
      *mesh = weld(parts, source.lattice().side, box.any());
      clip_to_box(*mesh, box);
    }
  });
  return true;
}

// Where a triangle budget samples the volume instead of counting all of it (BudgetSample): on
// lattices of 513 a side and up (volumes over 257 samples on a side), where the exact search costs
// more than the extraction it chooses for; smaller volumes keep the exact search, cheap there. The
// subtrees are those of level 18 (1.6 M tetrahedra, a 64th of the side across), one in 16 kept:
// with one in 8, at 1024^3 the estimates of T were within 1% of the meshes' counts for budgets of
// 100 k to 2 M, where level 12 (24,576 subtrees) missed by up to 9% and level 15 by up to 11%; one
// in 16 kept the meshes within the 90-100% window as often, for 8% less time (docs/METHOD.md, "A
// budget from a sample").
inline BudgetSample budget_sample_for(const Lattice& lattice) {
  return lattice.k >= 9 ? BudgetSample{18, 4} : BudgetSample{};
}

// `sample`: as budget_sample_for(the source's lattice) unless given (tests choose it). `memo`: the
// budgets already settled over this source (an open isotope::Source's); a budget found there is
// extracted at once, one not found is remembered once settled. A distributed extraction neither
// looks nor remembers, so that every rank searches alike.
template <TraversalSource Source>
Mesh extract_adaptive(const Source& source, const ExtractOptions& options, ExtractStats* stats,
                      std::optional<BudgetSample> sample = std::nullopt, BudgetMemo* memo = nullptr) {
  using namespace traversal;
  const auto start = std::chrono::steady_clock::now();
  options.validate();
  ExtractOptions in_codes = options;  // identity unless the source holds quantized codes
  const double offset = source.value_offset(), scale = source.value_scale();
  // What one code of delta's weight is worth: |X| scales with the values, |X| times a gradient
  // with their square.
  const double weight_scale = std::array<double, 3>{scale, scale * scale, 1.0}[static_cast<size_t>(options.weight)];
  if (offset != 0 || scale != 1) {
    in_codes.iso = static_cast<float>((static_cast<double>(options.iso) - offset) / scale);
    in_codes.eps = threshold_in_codes(options.eps, scale);
    in_codes.delta = threshold_in_codes(options.delta, weight_scale);
  }
  // The split rule of in_codes as it stands: the budget's choices change its eps and delta.
  auto rule_now = [&] {
    return SplitRule(in_codes, source.lattice(), source.origin(), source.spacing(), source.error_fold());
  };
  ExtractStats total;
  const Distribution* group = options.distribution;
  // Distributed, each step that may fail runs under settle_together, so that a rank whose read
  // fails stops every rank instead of leaving them waiting at the next gather.
  auto together = [group](const auto& work) {
    if (group)
      settle_together(*group, work);
    else
      work();
  };
  // The eps a triangle budget chose, into in_codes and the stats.
  auto take_choice = [&](const BudgetChoice& c) {
    in_codes.eps = c.eps;
    in_codes.eps_ties = c.ties;
    total.chosen_eps = threshold_in_data(c.eps, scale);
    total.chosen_eps_ties = c.ties;
    total.next_eps = threshold_in_data(c.next_eps, scale);
    total.next_eps_ties = c.next_ties;
    total.next_triangles = c.next_triangles;
    total.budget_steps = c.steps;
    total.budget_sampled = c.sampled;
  };
  auto choose_exactly = [&] {
    in_codes.eps = 0, in_codes.eps_ties = -1;  // as the options gave them with a budget
    together([&] {
      const SplitRule rule = rule_now();
      take_choice(choose_eps_for_budget(source, rule, options.max_triangles));
    });
  };
  bool chosen = false;   // an eps is chosen for the budget
  bool sampled = false;  // and it is a sample's guess, for the mesh's count to confirm
  const BudgetSample budget_sample = sample.value_or(budget_sample_for(source.lattice()));
  if (group) memo = nullptr;
  const std::optional<BudgetMemo::Choice> remembered =
      memo && options.max_triangles > 0 ? memo->find(options, budget_sample) : std::nullopt;
  if (remembered) {
    in_codes.eps = remembered->eps;
    in_codes.eps_ties = remembered->eps_ties;
    in_codes.delta = remembered->delta;
    BudgetMemo::take_budget_part(remembered->stats, total);
    total.budget_remembered = true;
    chosen = true;
  }
  // The search reads the bricks its extraction will read: a paged source keeps its whole budget
  // from the start instead of finding that out after a window of misses.
  if constexpr (RereadHint<Source>)
    if (!remembered && options.max_triangles > 0) source.will_read_again();
  together([&] {
    if (remembered) return;
    if (options.auto_delta) {
      // Half the budget for the features kept, half for the geometry around them; when even with
      // every feature dropped the coarsest mesh takes more than half, all of it for the features.
      in_codes.delta = 0;
      const SplitRule rule = rule_now();
      BudgetChoice d;
      try {
        d = choose_delta_for_budget(source, rule, std::max<int64_t>(1, options.max_triangles / 2));
      } catch (const TriangleBudgetTooSmall&) {
        d = choose_delta_for_budget(source, rule, options.max_triangles);
      }
      in_codes.delta = d.eps;
      total.chosen_delta = threshold_in_data(d.eps, weight_scale);
      total.delta_floor_triangles = d.triangles;
    }
    if (options.max_triangles > 0) {
      if (!budget_sample.exact()) {
        const SplitRule rule = rule_now();
        const BudgetChoice c = choose_eps_for_budget(source, rule, options.max_triangles, budget_sample);
        // A guess of eps 0 (full resolution, or a cut within the diamonds of error 0), or none, is
        // left to the exact search: it alone can tell whether the whole mesh fits, or that no mesh
        // does. (A lattice without the sample's subtrees is counted exactly at once.)
        if (!c.sampled || (c.fits && c.eps != 0)) take_choice(c), chosen = true, sampled = c.sampled;
      }
    }
  });
  // A choice is kept once settled: an exact one at once (its extraction may yet be cancelled), a
  // sampled guess once its mesh confirmed it or the exact search replaced it.
  auto keep = [&] {
    if (!memo || options.max_triangles <= 0 || remembered) return;
    BudgetMemo::Choice settled{in_codes.eps, in_codes.eps_ties, in_codes.delta, {}};
    BudgetMemo::take_budget_part(total, settled.stats);
    memo->remember(options, budget_sample, settled);
  };
  if (options.max_triangles > 0 && !chosen) choose_exactly();
  if (!sampled) keep();
  auto finish = [&](Mesh mesh) {
    if (stats) {
      *stats = total;
      stats->seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    }
    return mesh;
  };
  // A sampled guess stands when its mesh holds between kSampleFloor and all of the budget; else
  // the exact search chooses, and the extraction runs again (docs/METHOD.md, "Focus and triangle
  // budget"). Every process counts the whole mesh, so all of them decide alike.
  const std::function<bool(int64_t)> guess_stands = [&](int64_t mine) {
    const int64_t count = group ? sum_over_ranks(*group, mine) : mine;
    return count <= options.max_triangles &&
           static_cast<double>(count) >= kSampleFloor * static_cast<double>(options.max_triangles);
  };
  Mesh mesh;
  if (sampled) {
    if (extract_pieces(source, in_codes, together, total, &mesh, guess_stands)) {
      keep();
      return finish(std::move(mesh));
    }
    // The guess did not stand: the exact choice, and its mesh.
    total.tets_visited = total.tets_emitted = total.tets_simplified = 0;
    total.ranks.clear();
    choose_exactly();
    keep();
  }
  // Full resolution only when every diamond of key 0 is refined: a budget's finest step may be a
  // cut within them (eps 0 and some tie classes), which is a mesh of fewer triangles.
  if (in_codes.eps == 0 && in_codes.eps_ties < 0 && finest_extract_applies(source.lattice())) {
    const SplitRule rule = rule_now();
    return finish(extract_finest(source, rule, &total));
  }
  extract_pieces(source, in_codes, together, total, &mesh, nullptr);
  return finish(std::move(mesh));
}

}  // namespace isotope
