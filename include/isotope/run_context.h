#pragma once
// How one call runs, apart from what it computes (as oneTBB's task_group_context is to a task
// group): its threads, a flag that stops it, who hears its progress, and the group of processes it
// is spread over. ExtractOptions and ConvertOptions say what the mesh or the store is; the same
// options give the same bytes under any RunContext.
//
//   std::atomic<bool> stop{false};  // set from a signal handler or another thread
//   isotope::RunContext run;
//   run.cancel = &stop;
//   run.progress = [](double f) { std::fprintf(stderr, "\r%3.0f%%", 100 * f); };
//   isotope::convert({"scan_512x512x512_uint16.raw"}, "scan.isotope", {}, run);
#include <atomic>

#include <isotope/distribution.h>
#include <isotope/progress.h>

namespace isotope {

// The most worker threads a face accepts.
inline constexpr int kMaxThreads = 4096;

struct RunContext {
  // The most worker threads the call uses, 1 .. kMaxThreads; 0: as many as the process allows. Set
  // as oneTBB's process-wide max_allowed_parallelism while the call runs (tbb::global_control), so
  // calls that run at the same time share the smallest of their limits.
  int threads = 0;
  // Set (by another thread, or a signal handler) to stop: an extraction then throws
  // ExtractionCancelled at its next piece or slab (or at the next tile of the hierarchy a Source
  // builds for it), a convert IoError("interrupted") at its next tile, and nothing is left behind.
  // nullptr: never.
  const std::atomic<bool>* cancel = nullptr;
  // Hears the fraction done of the call's long step (ProgressCallback): a convert, or the hierarchy
  // of a volume that an extraction builds first (isotope::Source). May throw to stop it.
  ProgressCallback progress;
  // Spread over a group of processes, each making the same call with the same options
  // (isotope::Distribution): the mesh on rank 0, or the store, is the same bytes as without;
  // every other rank gets an empty mesh. nullptr: this process alone.
  const Distribution* distribution = nullptr;
  // An extraction with a distribution: every rank keeps the mesh of its own share (welded within
  // the share; a vertex on the boundary between two shares is in both), and nothing is sent to
  // rank 0: for a mesh too large for one process to hold or write (isotope extract --parts).
  bool keep_shares = false;

  // Throws OptionError("threads", ...) for threads outside 0 .. kMaxThreads, in the words every
  // face uses. Every call that takes a RunContext calls it.
  void validate() const;
};

}  // namespace isotope
