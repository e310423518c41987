#include "tools/support/mpi_launcher.h"

#include <cstdlib>
#include <initializer_list>

namespace isotope::tools {
namespace {

// The first of NAMES that is set, as a number; -1 when none is.
int64_t first_number(std::initializer_list<const char*> names) {
  for (const char* name : names)
    if (const char* v = std::getenv(name)) return std::strtoll(v, nullptr, 10);
  return -1;
}

}  // namespace

MpiLauncher mpi_launcher() {
  MpiLauncher l;
  const int64_t rank = first_number({"OMPI_COMM_WORLD_RANK", "PMIX_RANK", "PMI_RANK"});
  const int64_t ranks = first_number({"OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "SLURM_STEP_NUM_TASKS", "SLURM_NTASKS"});
  l.launched = rank >= 0 || std::getenv("OMPI_COMM_WORLD_SIZE") != nullptr || std::getenv("PMI_SIZE") != nullptr;
  if (!l.launched) return l;
  l.rank = rank < 0 ? 0 : rank;
  l.ranks = ranks < 1 ? 0 : ranks;
  return l;
}

}  // namespace isotope::tools
