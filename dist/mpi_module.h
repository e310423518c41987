#pragma once
// MPI as a module of the isotope command (the command's modules, module_function): Open MPI's libraries
// are loaded only by a command that an MPI launcher started (mpirun, srun), so a command started
// alone starts without them.
#include "isotope/distribution.h"

namespace isotope {

// MPI for the life of the process: initialized when made, finalized when destroyed.
class MpiRuntime {
 public:
  virtual ~MpiRuntime() = default;
  virtual const Distribution& world() const = 0;
  // Ends every rank of the job (MPI_Abort): for a failure the other ranks cannot learn of.
  [[noreturn]] virtual void abort(int code) const = 0;
};

inline constexpr const char* kMpiModule = "isotope-mpi";
inline constexpr const char* kStartMpi = "isotope_start_mpi";
// MPI_Init_thread; the caller owns the result. Throws std::runtime_error if MPI cannot start.
extern "C" MpiRuntime* isotope_start_mpi(int* argc, char*** argv);
using StartMpi = decltype(isotope_start_mpi);

}  // namespace isotope
