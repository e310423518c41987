#pragma once
// The triangle budgets already settled over one source that stays open (a server's store, a Python
// session's volume): what each chose, by the options that decide it. A budget asked for again is
// then one extraction, without the search (docs/METHOD.md, "Focus and triangle budget"). The
// choice depends on the source's data and these options alone, never on the threads or the
// cache, so the mesh is the same, byte for byte, as the first time.
#include <bit>
#include <cstdint>
#include <deque>
#include <mutex>
#include <optional>

#include "engine/extract/triangle_budget.h"
#include "isotope/extract.h"

namespace isotope {

class BudgetMemo {
 public:
  // What a budget settled: the eps (and ties, and with auto_delta the delta) in the source's value
  // units, and the stats that report the choice.
  struct Choice {
    double eps = 0;
    int eps_ties = -1;
    double delta = 0;
    ExtractStats stats;  // its budget fields only (take_budget_part)
  };

  // At most this many choices are kept, the oldest forgotten first: a viewer asks for a few budgets
  // at a few isovalues, and an entry is a few hundred bytes.
  static constexpr size_t kCapacity = 256;

  std::optional<Choice> find(const ExtractOptions& options, const BudgetSample& sample) const {
    const std::lock_guard<std::mutex> lock(mutex_);
    const Entry* e = entry(options, sample);
    return e ? std::optional<Choice>(e->choice) : std::nullopt;
  }
  void remember(const ExtractOptions& options, const BudgetSample& sample, const Choice& choice) {
    const std::lock_guard<std::mutex> lock(mutex_);
    if (entry(options, sample)) return;  // two threads settled the same budget at once
    if (entries_.size() == kCapacity) entries_.pop_front();
    entries_.push_back(Entry{options, sample, choice});  // the question alone: no run context kept
  }
  // The fields of `from` that report a budget's choice, into `to`.
  static void take_budget_part(const ExtractStats& from, ExtractStats& to) {
    to.chosen_eps = from.chosen_eps, to.chosen_eps_ties = from.chosen_eps_ties;
    to.next_eps = from.next_eps, to.next_eps_ties = from.next_eps_ties, to.next_triangles = from.next_triangles;
    to.budget_steps = from.budget_steps, to.budget_sampled = from.budget_sampled;
    to.chosen_delta = from.chosen_delta, to.delta_floor_triangles = from.delta_floor_triangles;
  }
  void clear() {
    const std::lock_guard<std::mutex> lock(mutex_);
    entries_.clear();
  }
  size_t size() const {
    const std::lock_guard<std::mutex> lock(mutex_);
    return entries_.size();
  }

 private:
  // Everything that decides a budget's choice: the isovalue (bit for bit), the budget, the error,
  // the topology mode with its weight and delta, and the focus. (eps and eps_ties are not free with
  // a budget; cancel only stops it; a distribution is never remembered.)
  static bool same_question(const ExtractOptions& a, const ExtractOptions& b) {
    const bool focus = a.focus.has_value() == b.focus.has_value() &&
                       (!a.focus || (a.focus->point == b.focus->point && a.focus->radius == b.focus->radius));
    return std::bit_cast<uint32_t>(a.iso) == std::bit_cast<uint32_t>(b.iso) && a.max_triangles == b.max_triangles &&
           a.error == b.error && a.topology == b.topology && a.weight == b.weight &&
           std::bit_cast<uint64_t>(a.delta) == std::bit_cast<uint64_t>(b.delta) && a.auto_delta == b.auto_delta &&
           focus;
  }
  struct Entry {
    ExtractOptions options;
    BudgetSample sample;
    Choice choice;
  };
  // The entry of this question, or null; under mutex_.
  const Entry* entry(const ExtractOptions& options, const BudgetSample& sample) const {
    for (const Entry& e : entries_)
      if (e.sample.level == sample.level && e.sample.bits == sample.bits && same_question(e.options, options))
        return &e;
    return nullptr;
  }
  mutable std::mutex mutex_;
  std::deque<Entry> entries_;
};

}  // namespace isotope
