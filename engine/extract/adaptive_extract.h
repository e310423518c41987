#pragma once
// Adaptive extraction over any source of values and records (any TraversalSource): the traversal
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
#include "engine/extract/process_group.h"
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
template <TraversalSource Source>
bool extract_pieces(const Source& source, const ExtractCall& options, const ProcessGroup& group, ExtractStats& total,
                    Mesh* mesh, const std::function<bool(int64_t)>& check) {
  using namespace traversal;
  const SplitRule rule(options, source.lattice(), source.origin(), source.spacing(), source.error_fold());
  std::vector<Piece> pieces;
  group.step([&] {
    // scoped: a paged source's reader lets its bricks go before the pieces run
    Traversal<Source> top(source, rule);
    pieces = top.split(piece_level(source.lattice()));
    total.tets_visited = top.tets_visited();
    total.tets_simplified = top.tets_simplified();
  });
  // Spread over processes, this one runs its share of the pieces, and rank 0 welds them all
  // (gather_parts). Every other rank returns an empty mesh.
  const ProcessGroup::Share share = group.share_of(pieces.size(), [&](size_t first, size_t last, double* out) {
    piece_costs(source, rule, pieces, first, last, out);
  });
  const auto work_start = std::chrono::steady_clock::now();
  std::vector<PartMesh> parts(share.last - share.first);
  LendingPool<LevelScratch<Source>> levels;
  RankLoad load;  // this process's share of the pieces, without waiting for the others
  group.step([&] {
    parallel_for_in_order(int64_t{0}, static_cast<int64_t>(parts.size()), [&](int64_t j) {
      const int64_t i = static_cast<int64_t>(share.first) + j;
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
    load.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - work_start).count();
  });
  if (group.spread()) {
    for (size_t i = share.first; i < share.last; ++i) load.cost += share.costs[i];
    for (const PartMesh& p : parts) load.work += p.tets_visited;
    load.items = static_cast<int64_t>(parts.size());
    if constexpr (requires { source.bytes_read(); }) load.bytes_read = source.bytes_read();
    total.ranks = group.loads(load);
  }
  levels.clear();  // the walks' scratch and welding tables, before the weld takes its memory
  // What reaches past the data box is clipped to it once welded (BoxClip).
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
  parts = group.to_welder(std::move(parts), options.keep_shares);
  for (const PartMesh& p : parts) {
    total.tets_visited += p.tets_visited;
    total.tets_emitted += p.tets_emitted;
    total.tets_simplified += p.tets_simplified;
  }
  // The process that makes the mesh welds; the others wait, so that running out of memory in the
  // weld stops them too.
  group.step([&] {
    if (group.makes_mesh(options.keep_shares)) {
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

// One adaptive extraction, pass by pass (extract_adaptive below is their driver): the options in
// the source's value units; a triangle budget's choice of eps (and delta), remembered, searched on a
// sample, or searched exactly; then the mesh at that choice.
template <TraversalSource Source>
class AdaptiveExtraction {
 public:
  AdaptiveExtraction(const Source& source, const ExtractCall& options, std::optional<BudgetSample> sample,
                     BudgetMemo* memo)
      : source_(source),
        options_(options),
        group_(options.distribution),
        sample_(sample.value_or(budget_sample_for(source.lattice()))),
        memo_(group_.spread() ? nullptr : memo),  // every rank searches alike
        in_codes_(options) {
    // Identity unless the source holds quantized codes. What one code of delta's weight is worth:
    // |X| scales with the values, |X| times a gradient with their square.
    const double offset = source.value_offset();
    scale_ = source.value_scale();
    weight_scale_ = std::array<double, 3>{scale_, scale_ * scale_, 1.0}[static_cast<size_t>(options.weight)];
    if (offset != 0 || scale_ != 1) {
      in_codes_.iso = static_cast<float>((static_cast<double>(options.iso) - offset) / scale_);
      in_codes_.eps = threshold_in_codes(options.eps, scale_);
      in_codes_.delta = threshold_in_codes(options.delta, weight_scale_);
    }
  }

  // A budget settled before over this source (the memo's), taken as it was.
  void recall_choice() {
    if (memo_ && options_.max_triangles > 0) remembered_ = memo_->find(options_, sample_);
    if (!remembered_) return;
    in_codes_.eps = remembered_->eps;
    in_codes_.eps_ties = remembered_->eps_ties;
    in_codes_.delta = remembered_->delta;
    BudgetMemo::take_budget_part(remembered_->stats, total_);
    total_.budget_remembered = true;
    chosen_ = true;
  }

  // Unless recalled: delta for auto_delta, and on a large lattice the sample's guess of eps.
  void search_choice() {
    if (remembered_ || options_.max_triangles <= 0) return;
    // The search reads the bricks its extraction will read: a paged source keeps its whole budget
    // from the start instead of finding that out after a window of misses.
    if constexpr (RereadHint<Source>) source_.will_read_again();
    group_.step([&] {
      if (options_.auto_delta) choose_delta();
      if (!sample_.exact()) {
        const BudgetChoice c = choose_eps_for_budget(source_, rule(), options_.max_triangles, sample_);
        // A guess of eps 0 (full resolution, or a cut within the diamonds of error 0), or none, is
        // left to the exact search: it alone can tell whether the whole mesh fits, or that no mesh
        // does. (A lattice without the sample's subtrees is counted exactly at once.)
        if (!c.sampled || (c.fits && c.eps != 0)) take(c), chosen_ = true, sampled_ = c.sampled;
      }
    });
  }

  // The exact search where nothing chose yet; the choice kept, unless a sampled guess awaits its mesh.
  void settle_choice() {
    if (options_.max_triangles > 0 && !chosen_) choose_exactly();
    if (!sampled_) keep();
  }

  // A sampled guess's mesh, into MESH, when it holds between kSampleFloor and all of the budget;
  // otherwise false, after the exact search has replaced the guess (docs/METHOD.md, "Focus and
  // triangle budget"). Every process counts the whole mesh, so all of them decide alike.
  bool mesh_of_guess(Mesh& mesh) {
    if (!sampled_) return false;
    const std::function<bool(int64_t)> stands = [&](int64_t mine) {
      const int64_t count = group_.sum(mine);
      return count <= options_.max_triangles &&
             static_cast<double>(count) >= kSampleFloor * static_cast<double>(options_.max_triangles);
    };
    if (extract_pieces(source_, in_codes_, group_, total_, &mesh, stands)) {
      keep();
      return true;
    }
    total_.tets_visited = total_.tets_emitted = total_.tets_simplified = 0;
    total_.ranks.clear();
    choose_exactly();
    keep();
    return false;
  }

  // The mesh at the choice. Full resolution only when every diamond of key 0 is refined: a
  // budget's finest step may be a cut within them (eps 0 and some tie classes), a mesh of fewer
  // triangles.
  Mesh mesh_at_choice() {
    if (in_codes_.eps == 0 && in_codes_.eps_ties < 0 && finest_extract_applies(source_.lattice()))
      return extract_finest(source_, rule(), &total_);
    Mesh mesh;
    extract_pieces(source_, in_codes_, group_, total_, &mesh, nullptr);
    return mesh;
  }

  const ExtractStats& stats() const { return total_; }

 private:
  // The split rule of the options as they stand: a budget's choices change their eps and delta.
  traversal::SplitRule rule() const {
    return traversal::SplitRule(in_codes_, source_.lattice(), source_.origin(), source_.spacing(),
                                source_.error_fold());
  }
  // An eps a triangle budget chose, into the options and the stats.
  void take(const BudgetChoice& c) {
    in_codes_.eps = c.eps;
    in_codes_.eps_ties = c.ties;
    total_.chosen_eps = threshold_in_data(c.eps, scale_);
    total_.chosen_eps_ties = c.ties;
    total_.next_eps = threshold_in_data(c.next_eps, scale_);
    total_.next_eps_ties = c.next_ties;
    total_.next_triangles = c.next_triangles;
    total_.budget_steps = c.steps;
    total_.budget_sampled = c.sampled;
  }
  // Half the budget for the features kept, half for the geometry around them; when even with
  // every feature dropped the coarsest mesh takes more than half, all of it for the features.
  void choose_delta() {
    in_codes_.delta = 0;
    const traversal::SplitRule r = rule();
    BudgetChoice d;
    try {
      d = choose_delta_for_budget(source_, r, std::max<int64_t>(1, options_.max_triangles / 2));
    } catch (const TriangleBudgetTooSmall&) {
      d = choose_delta_for_budget(source_, r, options_.max_triangles);
    }
    in_codes_.delta = d.eps;
    total_.chosen_delta = threshold_in_data(d.eps, weight_scale_);
    total_.delta_floor_triangles = d.triangles;
  }
  void choose_exactly() {
    in_codes_.eps = 0, in_codes_.eps_ties = -1;  // as the options gave them with a budget
    group_.step([&] { take(choose_eps_for_budget(source_, rule(), options_.max_triangles)); });
  }
  // A choice is kept once settled: an exact one at once (its extraction may yet be cancelled), a
  // sampled guess once its mesh confirmed it or the exact search replaced it.
  void keep() {
    if (!memo_ || options_.max_triangles <= 0 || remembered_) return;
    BudgetMemo::Choice settled{in_codes_.eps, in_codes_.eps_ties, in_codes_.delta, {}};
    BudgetMemo::take_budget_part(total_, settled.stats);
    memo_->remember(options_, sample_, settled);
  }

  const Source& source_;
  const ExtractCall options_;
  const ProcessGroup group_;
  const BudgetSample sample_;
  BudgetMemo* const memo_;
  ExtractCall in_codes_;  // the options in the source's value units
  double scale_ = 1, weight_scale_ = 1;
  ExtractStats total_;
  std::optional<BudgetMemo::Choice> remembered_;
  bool chosen_ = false;   // an eps is chosen for the budget
  bool sampled_ = false;  // and it is a sample's guess, for the mesh's count to confirm
};

// `sample`: as budget_sample_for(the source's lattice) unless given (tests choose it). `memo`: the
// budgets already settled over this source (an open isotope::Source's); a budget found there is
// extracted at once, one not found is remembered once settled. A distributed extraction neither
// looks nor remembers, so that every rank searches alike.
template <TraversalSource Source>
Mesh extract_adaptive(const Source& source, const ExtractCall& options, ExtractStats* stats,
                      std::optional<BudgetSample> sample = std::nullopt, BudgetMemo* memo = nullptr) {
  const auto start = std::chrono::steady_clock::now();
  options.validate();
  AdaptiveExtraction<Source> run(source, options, sample, memo);
  run.recall_choice();
  run.search_choice();
  run.settle_choice();
  Mesh mesh;
  if (!run.mesh_of_guess(mesh)) mesh = run.mesh_at_choice();
  if (stats) {
    *stats = run.stats();
    stats->seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }
  return mesh;
}

}  // namespace isotope
