#pragma once
// Work shared among processes: what the engine asks of a group of processes (MPI ranks) when one
// extraction or one conversion is spread over them, without depending on MPI. The MPI group is
// the command's MpiDistribution; a host program with its own communicator implements the two gathers.
//
// Every process runs the same call with the same options and the same Distribution (rank r of R):
// each takes a contiguous share of the work, chosen the same way on every process, and rank 0
// receives the rest and finishes: the mesh (or the store) is the one a single process makes, byte
// for byte (docs/DISTRIBUTED.md). A failure on any process makes every process throw, with the
// failing rank's message, at the next point where they meet (settle_together), so none waits for
// another forever.
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include <isotope/error.h>

namespace isotope {

class Distribution {
 public:
  virtual ~Distribution() = default;
  virtual int rank() const = 0;
  virtual int ranks() const = 0;
  // Collective: every process's bytes, on every process, in rank order. For small things
  // (sizes, counts, a failure's message).
  virtual std::vector<std::vector<uint8_t>> all_gather(const std::vector<uint8_t>& mine) const = 0;
  // Collective: every process's bytes on rank 0, in rank order (rank 0's own included); nothing
  // elsewhere. For large things (the parts of a mesh), of any size. When rank 0 cannot hold them
  // it must still take part to the end, then throw (the engine calls it under settle_together, so
  // that every rank learns of it).
  virtual std::vector<std::vector<uint8_t>> gather(const std::vector<uint8_t>& mine) const = 0;
};

// Collective: runs `work` on this process, then learns from every process whether its work
// threw. When any did, every process throws DistributedError with the message of the lowest
// failing rank (a DistributedError from a nested call passes through as it is).
void settle_together(const Distribution& group, const std::function<void()>& work);
// The same where the call may run alone (GROUP null, as RunContext::distribution): WORK just runs,
// so that a driver calls one step either way.
inline void settle_together(const Distribution* group, const std::function<void()>& work) {
  if (group)
    settle_together(*group, work);
  else
    work();
}

// Where each of `ranks` contiguous shares of items with these costs begins (ranks + 1 bounds, the
// last = costs.size()): each share's cost as close to total / ranks as whole items allow. The
// same on every process for the same costs.
std::vector<size_t> share_by_cost(const std::vector<double>& costs, int ranks);

}  // namespace isotope
