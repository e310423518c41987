#include "dist/mpi_distribution.h"

#include <algorithm>
#include <climits>
#include <cstdlib>
#include <new>
#include <numeric>
#include <stdexcept>
#include <string>

#include "isotope/error.h"

namespace isotope {
namespace {

constexpr uint64_t kChunk = uint64_t{64} << 20;  // 64 MiB: MPI counts are ints, and a drain's room
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
  if (total > INT_MAX) throw Error("all_gather: more than 2 GiB");
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
  // Out of memory here, rank 0 still receives every piece (into one chunk's room, over and over),
  // so that no sender waits forever, and throws after.
  std::vector<std::vector<uint8_t>> out(static_cast<size_t>(ranks_));
  std::vector<uint8_t> drain;
  bool failed = false;
  try {
    out[0] = mine;
  } catch (const std::bad_alloc&) {
    failed = true;
  }
  for (int r = 1; r < ranks_; ++r) {
    std::vector<uint8_t>& bytes = out[static_cast<size_t>(r)];
    const uint64_t theirs = sizes[static_cast<size_t>(r)];
    if (!failed) try {
        bytes.resize(theirs);
      } catch (const std::bad_alloc&) {
        failed = true;
      }
    if (failed) {
      for (std::vector<uint8_t>& o : out) std::vector<uint8_t>().swap(o);  // what was received goes
      drain.resize(std::min(kChunk, theirs));
    }
    for (uint64_t at = 0; at < theirs; at += kChunk)
      MPI_Recv(failed ? drain.data() : bytes.data() + at, static_cast<int>(std::min(kChunk, theirs - at)), MPI_BYTE, r,
               kTag, comm_, MPI_STATUS_IGNORE);
  }
  if (failed) throw std::bad_alloc();
  return out;
}

MpiSession::MpiSession(int* argc, char*** argv) {
  int provided = 0;
  if (MPI_Init_thread(argc, argv, MPI_THREAD_FUNNELED, &provided) != MPI_SUCCESS)
    throw Error("MPI could not be initialized");
  world_ = MpiDistribution(MPI_COMM_WORLD);
}

MpiSession::~MpiSession() { MPI_Finalize(); }

void MpiSession::abort(int code) const {
  MPI_Abort(MPI_COMM_WORLD, code);
  std::_Exit(code);  // MPI_Abort does not return; should it, the rank still ends
}

extern "C" MpiRuntime* isotope_start_mpi(int* argc, char*** argv) { return new MpiSession(argc, argv); }

}  // namespace isotope
