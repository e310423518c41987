#pragma once
// Shared fixtures of the engine tests: volumes, sweeps, and mesh comparisons.
#include <sys/resource.h>

#include <array>
#include <csignal>
#include <cstdint>
#include <string>
#include <vector>

#include "engine/extract/extract_drivers.h"
#include "io/store/store_writer.h"
#include "isotope/mesh.h"
#include "isotope/volume.h"

namespace isotope::testing {

struct SharedVolume {
  std::string name, file;
  std::array<float, 3> isovalues;
};

// The four volumes of ../shared/data with their suggested isovalues (data README).
const std::vector<SharedVolume>& shared_volumes();
Volume load_shared(const SharedVolume& v);

// Triangles as sorted position triples, sorted: equal iff the meshes have the same triangles.
std::vector<std::array<std::array<float, 3>, 3>> triangle_set(const Mesh& mesh);

// Boundary edges that do not lie in a face of the data box (cracks); physical coordinates.
int64_t interior_boundary_edges(const Mesh& mesh, const Volume& volume);
// Vertices outside the data box.
int64_t vertices_outside_box(const Mesh& mesh, const Volume& volume);

// A small grid with a caller-chosen size, values from f(x, y, z) at integer nodes.
template <class F>
Volume make_volume(std::array<int64_t, 3> dims, F f) {
  Volume v;
  v.dims = dims;
  v.values.resize(static_cast<size_t>(dims[0] * dims[1] * dims[2]));
  for (int64_t z = 0; z < dims[2]; ++z)
    for (int64_t y = 0; y < dims[1]; ++y)
      for (int64_t x = 0; x < dims[0]; ++x) v.values[v.index(x, y, z)] = static_cast<float>(f(x, y, z));
  return v;
}

// Writes `v` into DIR as a float32 raw file, converts it to DIR/NAME.isotope (removing the raw
// file) and returns the store's path. A float32 raw carries unit spacing and origin 0.
std::string write_store(const Volume& v, const std::string& dir, const std::string& name,
                        const ConvertOptions& options = {}, const RunContext& run = {});

// Cuts a sub-box out of a volume (for dimensions that are not 2^k + 1).
Volume crop(const Volume& v, std::array<int64_t, 3> dims);

// While it lives, this process's writes past BYTES of a file fail (EFBIG), the signal that would
// end the process (SIGXFSZ) ignored: a file size limit, as a full disk, in a test.
class FileSizeLimit {
 public:
  explicit FileSizeLimit(rlim_t bytes) : signal_was_(std::signal(SIGXFSZ, SIG_IGN)) {
    getrlimit(RLIMIT_FSIZE, &was_);
    rlimit limit = was_;
    limit.rlim_cur = bytes;
    setrlimit(RLIMIT_FSIZE, &limit);
  }
  ~FileSizeLimit() {
    setrlimit(RLIMIT_FSIZE, &was_);
    std::signal(SIGXFSZ, signal_was_);
  }
  FileSizeLimit(const FileSizeLimit&) = delete;
  FileSizeLimit& operator=(const FileSizeLimit&) = delete;

 private:
  rlimit was_{};
  void (*signal_was_)(int);
};

// Whether the page cache holds the byte at `offset` of `file`, without reading it in: 1 it does, 0 it does not, -1 this
// cannot be told (the file does not open, or its file system refuses RWF_NOWAIT reads).
int page_cached(const std::string& file, uint64_t offset);
// Reads the file whole, so that the page cache holds it, and says whether it then holds every
// page (mincore; false too when that cannot be told).
bool read_into_page_cache(const std::string& file);
// Writes the file's dirty pages and asks the kernel to drop the file from the page cache. False
// when either fails; a file system in memory may keep the pages all the same (page_cached tells).
bool drop_from_page_cache(const std::string& file);
// This process's bytes written into the page cache and dropped before they reached the disk (a
// file removed before its writeback), from /proc/self/io; -1 where the kernel does not say.
int64_t cancelled_write_bytes();

}  // namespace isotope::testing
