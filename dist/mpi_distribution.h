#pragma once
// The processes of an MPI communicator as a Distribution (isotope::Distribution): what
// `mpirun -n R isotope extract|convert` runs on (docs/DISTRIBUTED.md). Only the thread that
// initialized MPI calls it (MPI_THREAD_FUNNELED): the engine gathers between its parallel loops,
// never inside them.
#include <mpi.h>

#include <cstdint>
#include <vector>

#include "dist/mpi_module.h"
#include "isotope/distribution.h"

namespace isotope {

class MpiDistribution : public Distribution {
 public:
  explicit MpiDistribution(MPI_Comm comm = MPI_COMM_WORLD);
  int rank() const override { return rank_; }
  int ranks() const override { return ranks_; }
  std::vector<std::vector<uint8_t>> all_gather(const std::vector<uint8_t>& mine) const override;
  // Point to point, in pieces of 64 MiB: MPI counts are ints, a rank's mesh may be larger.
  std::vector<std::vector<uint8_t>> gather(const std::vector<uint8_t>& mine) const override;

 private:
  MPI_Comm comm_;
  int rank_ = 0, ranks_ = 1;
};

// MPI for the life of a process that an MPI launcher started (mpirun, srun: the isotope command
// tells by the variables they set), and nothing at all for one started otherwise, so that the same
// isotope binary runs alone without an MPI runtime being involved.
class MpiSession : public MpiRuntime {
 public:
  MpiSession(int* argc, char*** argv);  // MPI_Init_thread; throws std::runtime_error if that fails
  ~MpiSession() override;               // MPI_Finalize
  MpiSession(const MpiSession&) = delete;
  MpiSession& operator=(const MpiSession&) = delete;
  const MpiDistribution& world() const override { return world_; }
  [[noreturn]] void abort(int code) const override;

 private:
  MpiDistribution world_{MPI_COMM_NULL};
};

}  // namespace isotope
