#pragma once
// Whether an MPI launcher (mpirun, mpiexec, srun) started this process, and as one of how many
// ranks, read from the variables the launchers set; no MPI library involved, so that an isotope
// built without MPI can tell too, and refuse rather than run the whole job once per rank
// (docs/DISTRIBUTED.md, "Launchers").
#include <cstdint>

namespace isotope::tools {

struct MpiLauncher {
  bool launched = false;
  int64_t ranks = 1;  // 0: launched, but the launcher does not say how many
  int64_t rank = 0;
};

// Open MPI (OMPI_COMM_WORLD_*), MPICH and Intel MPI's Hydra and Slurm's PMI (PMI_*), PMIx
// (PMIX_RANK, with Slurm's task count). Not SLURM_PROCID alone: a batch script's own shell has it,
// without a launcher behind it.
MpiLauncher mpi_launcher();

}  // namespace isotope::tools
