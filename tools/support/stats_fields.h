#pragma once
// What an extraction measured of itself (isotope::ExtractStats), field by field under the names the
// faces report them by: the one place those names are written. The command's JSON report (and the
// server's, which is the same) and the Python module's stats dict both walk these groups, so a
// field added to ExtractStats and here reaches every face under one name.
//
//   for_each_work_stat(stats, [&](const char* name, auto value) { json[name] = value; });
#include <isotope/extract.h>

namespace isotope::tools {

// The work done: every extraction has these (the report's "extract" block).
template <class Visit>
void for_each_work_stat(const ExtractStats& s, Visit&& visit) {
  visit("seconds", s.seconds);
  visit("tets_visited", s.tets_visited);
  visit("tets_emitted", s.tets_emitted);
  visit("tets_simplified", s.tets_simplified);
}

// What a triangle budget chose (meaningful with ExtractOptions::max_triangles > 0).
template <class Visit>
void for_each_budget_stat(const ExtractStats& s, Visit&& visit) {
  visit("chosen_eps", s.chosen_eps);
  visit("chosen_eps_ties", s.chosen_eps_ties);
  visit("next_eps", s.next_eps);
  visit("next_eps_ties", s.next_eps_ties);
  visit("next_triangles", s.next_triangles);
  visit("budget_steps", s.budget_steps);
  visit("budget_sampled", s.budget_sampled);
  visit("budget_remembered", s.budget_remembered);
}

// What an automatic delta chose (meaningful when chosen_delta >= 0; -1 when none was).
template <class Visit>
void for_each_delta_stat(const ExtractStats& s, Visit&& visit) {
  visit("chosen_delta", s.chosen_delta);
  visit("delta_floor_triangles", s.delta_floor_triangles);
}

// One process's load in a distributed extraction (ExtractStats::ranks).
template <class Visit>
void for_each_load_stat(const RankLoad& l, Visit&& visit) {
  visit("cost", l.cost);
  visit("items", l.items);
  visit("work", l.work);
  visit("seconds", l.seconds);
  visit("bytes_read", l.bytes_read);
}

}  // namespace isotope::tools
