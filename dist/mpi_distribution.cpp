#include "dist/mpi_distribution.h"

#include <algorithm>
#include <climits>
#include <cstdlib>
#include <numeric>
#include <stdexcept>
#include <string>

namespace isotope {
namespace {

constexpr uint64_t kChunk = uint64_t{1} << 30;
constexpr int kTag = 7041;

}  // namespace

MpiDistribution::MpiDistribution(MPI_Comm comm) : comm_(comm) {
  if (comm == MPI_COMM_NULL) return;
  MPI_Comm_rank(comm, &rank_);
  MPI_Comm_size(comm, &ranks_);
}

std::vector<std::vector<uint8_t>> MpiDistribution::all_gather(const std::vector<uint8_t>& mine) const {
  std::vector<uint64_t> sizes(static_cast<size_t>(ranks_));
  const uint64_t size = mine.size();
  MPI_Allgather(&size, 1, MPI_UINT64_T, sizes.data(), 1, MPI_UINT64_T, comm_);
  const uint64_t total = std::accumulate(sizes.begin(), sizes.end(), uint64_t{0});
  if (total > INT_MAX) throw std::runtime_error("all_gather: more than 2 GiB");
  std::vector<int> counts(sizes.begin(), sizes.end()), displs(static_cast<size_t>(ranks_), 0);
  for (size_t r = 1; r < displs.size(); ++r) displs[r] = displs[r - 1] + counts[r - 1];
  std::vector<uint8_t> all(std::max<uint64_t>(total, 1));
  MPI_Allgatherv(mine.data(), static_cast<int>(size), MPI_BYTE, all.data(), counts.data(), displs.data(), MPI_BYTE,
                 comm_);
  std::vector<std::vector<uint8_t>> out(static_cast<size_t>(ranks_));
  for (size_t r = 0; r < out.size(); ++r) out[r].assign(all.begin() + displs[r], all.begin() + displs[r] + counts[r]);
  return out;
}

std::vector<std::vector<uint8_t>> MpiDistribution::gather(const std::vector<uint8_t>& mine) const {
  std::vector<uint64_t> sizes(static_cast<size_t>(ranks_));
  const uint64_t size = mine.size();
  MPI_Gather(&size, 1, MPI_UINT64_T, sizes.data(), 1, MPI_UINT64_T, 0, comm_);
  if (rank_ != 0) {
    for (uint64_t at = 0; at < size; at += kChunk)
      MPI_Send(mine.data() + at, static_cast<int>(std::min(kChunk, size - at)), MPI_BYTE, 0, kTag, comm_);
    return {};
  }
  std::vector<std::vector<uint8_t>> out(static_cast<size_t>(ranks_));
  out[0] = mine;
  for (int r = 1; r < ranks_; ++r) {
    std::vector<uint8_t>& bytes = out[static_cast<size_t>(r)];
    bytes.resize(sizes[static_cast<size_t>(r)]);
    for (uint64_t at = 0; at < bytes.size(); at += kChunk)
      MPI_Recv(bytes.data() + at, static_cast<int>(std::min<uint64_t>(kChunk, bytes.size() - at)), MPI_BYTE, r, kTag,
               comm_, MPI_STATUS_IGNORE);
  }
  return out;
}

bool MpiSession::launched() {
  for (const char* name : {"OMPI_COMM_WORLD_SIZE", "PMIX_RANK", "PMI_RANK", "PMI_SIZE", "SLURM_PROCID"})
    if (std::getenv(name)) return true;
  return false;
}

MpiSession::MpiSession(int* argc, char*** argv) {
  int provided = 0;
  if (MPI_Init_thread(argc, argv, MPI_THREAD_FUNNELED, &provided) != MPI_SUCCESS)
    throw std::runtime_error("MPI could not be initialized");
  world_ = MpiDistribution(MPI_COMM_WORLD);
}

MpiSession::~MpiSession() { MPI_Finalize(); }

}  // namespace isotope
