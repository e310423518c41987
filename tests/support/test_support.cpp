#include "tests/support/test_support.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/uio.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <filesystem>
#include <fstream>

#include "io/volume/box_reader.h"
#include "io/volume/raw_reader.h"

namespace isotope::testing {

const std::vector<SharedVolume>& shared_volumes() {
  static const std::vector<SharedVolume> v = {
      {"ironProt", "ironProt_68x68x68_uint8.raw", {32.5f, 128.5f, 224.5f}},
      {"neghip", "neghip_66x66x66_uint8.raw", {32.5f, 128.5f, 224.5f}},
      {"hydrogen", "hydrogen_64x64x64_float32.raw", {0.005f, 0.05f, 0.3f}},
      {"bolt", "bolt_70x123x66_uint8.raw", {64.5f, 240.5f, 254.5f}},
  };
  return v;
}

Volume load_shared(const SharedVolume& v) {
  const std::string path = std::string(ISOTOPE_TEST_DATA) + "/" + v.file;
  return read_raw(path, *parse_raw_name(path));
}

std::vector<std::array<std::array<float, 3>, 3>> triangle_set(const Mesh& mesh) {
  std::vector<std::array<std::array<float, 3>, 3>> s;
  s.reserve(mesh.triangles.size());
  for (const auto& t : mesh.triangles) {
    std::array<std::array<float, 3>, 3> p{mesh.positions[t[0]], mesh.positions[t[1]], mesh.positions[t[2]]};
    std::sort(p.begin(), p.end());
    s.push_back(p);
  }
  std::sort(s.begin(), s.end());
  return s;
}

namespace {
// Which faces of the data box a point lies on, as a bit mask (x-, x+, y-, y+, z-, z+).
int box_faces(const std::array<float, 3>& p, const Volume& v) {
  int mask = 0;
  for (int a = 0; a < 3; ++a) {
    const double lo = v.origin[a], hi = v.origin[a] + v.spacing[a] * static_cast<double>(v.dims[a] - 1);
    const double tol = 1e-5 * std::max(1.0, std::fabs(hi - lo));
    if (std::fabs(p[a] - lo) <= tol) mask |= 1 << (2 * a);
    if (std::fabs(p[a] - hi) <= tol) mask |= 2 << (2 * a);
  }
  return mask;
}
}  // namespace

int64_t interior_boundary_edges(const Mesh& mesh, const Volume& volume) {
  std::vector<std::pair<uint64_t, int>> edges;
  for (const auto& t : mesh.triangles)
    for (int i = 0; i < 3; ++i) {
      const uint32_t a = t[i], b = t[(i + 1) % 3];
      edges.push_back({uint64_t{std::min(a, b)} << 32 | std::max(a, b), 0});
    }
  std::sort(edges.begin(), edges.end());
  int64_t cracks = 0;
  for (size_t i = 0; i < edges.size();) {
    size_t j = i;
    while (j < edges.size() && edges[j].first == edges[i].first) ++j;
    if (j - i == 1) {
      const auto a = static_cast<uint32_t>(edges[i].first >> 32), b = static_cast<uint32_t>(edges[i].first);
      if ((box_faces(mesh.positions[a], volume) & box_faces(mesh.positions[b], volume)) == 0) ++cracks;
    }
    i = j;
  }
  return cracks;
}

int64_t vertices_outside_box(const Mesh& mesh, const Volume& v) {
  int64_t n = 0;
  for (const auto& p : mesh.positions)
    for (int a = 0; a < 3; ++a) {
      const double lo = v.origin[a], hi = v.origin[a] + v.spacing[a] * static_cast<double>(v.dims[a] - 1);
      const double tol = 1e-5 * std::max(1.0, std::fabs(hi - lo));
      if (p[a] < lo - tol || p[a] > hi + tol) {
        ++n;
        break;
      }
    }
  return n;
}

Volume crop(const Volume& v, std::array<int64_t, 3> dims) {
  Volume c;
  c.dims = dims;
  c.spacing = v.spacing;
  c.origin = v.origin;
  c.values.resize(static_cast<size_t>(dims[0] * dims[1] * dims[2]));
  for (int64_t z = 0; z < dims[2]; ++z)
    for (int64_t y = 0; y < dims[1]; ++y)
      for (int64_t x = 0; x < dims[0]; ++x) c.values[c.index(x, y, z)] = v.at(x, y, z);
  return c;
}

std::string write_store(const Volume& v, const std::string& dir, const std::string& name, const ConvertOptions& options,
                        const RunContext& run) {
  const std::string dims =
      std::to_string(v.dims[0]) + "x" + std::to_string(v.dims[1]) + "x" + std::to_string(v.dims[2]);
  const std::string raw = dir + "/" + name + "_" + dims + "_float32.raw";
  std::ofstream(raw, std::ios::binary)
      .write(reinterpret_cast<const char*>(v.values.data()), static_cast<std::streamsize>(v.values.size() * 4));
  const std::string store = dir + "/" + name + ".isotope";
  const auto input = open_box_reader({raw, std::nullopt, std::nullopt}, dir);
  convert_to_store(*input, store, ConvertCall(options, run));
  std::filesystem::remove(raw);
  return store;
}

int page_cached(const std::string& file, uint64_t offset) {
  const int fd = ::open(file.c_str(), O_RDONLY);
  if (fd < 0) return -1;
  // Residency first, with mincore, which reads nothing: a RWF_NOWAIT read of a page the cache does
  // not hold starts the kernel reading it (and its read-ahead window) while it answers EAGAIN, so
  // a probe of a dropped store read much of it back, and the extraction after it found every brick
  // in memory and never waited.
  const uint64_t page = offset & ~uint64_t{4095};
  void* map = ::mmap(nullptr, 4096, PROT_READ, MAP_SHARED, fd, static_cast<off_t>(page));
  if (map == MAP_FAILED) {
    ::close(fd);
    return -1;
  }
  unsigned char resident = 0;
  const bool known = ::mincore(map, 4096, &resident) == 0;
  ::munmap(map, 4096);
  if (!known || (resident & 1) == 0) {
    ::close(fd);
    return known ? 0 : -1;
  }
  // Resident: a RWF_NOWAIT read of it must then succeed (the store's reader relies on it).
  char byte = 0;
  iovec v{&byte, 1};
  const ssize_t got = ::preadv2(fd, &v, 1, static_cast<off_t>(offset), RWF_NOWAIT);
  const int error = errno;
  ::close(fd);
  return got == 1 ? 1 : (got < 0 && error == EAGAIN) ? 0 : -1;
}

bool read_into_page_cache(const std::string& file) {
  {
    std::ifstream in(file, std::ios::binary);
    std::vector<char> chunk(size_t{1} << 20);
    while (in.read(chunk.data(), static_cast<std::streamsize>(chunk.size())) || in.gcount() > 0) {
    }
  }
  // Then whether every page stayed: under memory pressure the kernel may drop what was just read.
  const int fd = ::open(file.c_str(), O_RDONLY);
  if (fd < 0) return false;
  const auto bytes = static_cast<size_t>(::lseek(fd, 0, SEEK_END));
  void* map = bytes > 0 ? ::mmap(nullptr, bytes, PROT_READ, MAP_SHARED, fd, 0) : MAP_FAILED;
  ::close(fd);
  if (map == MAP_FAILED) return false;
  std::vector<unsigned char> resident((bytes + 4095) / 4096);
  const bool known = ::mincore(map, bytes, resident.data()) == 0;
  ::munmap(map, bytes);
  return known && std::all_of(resident.begin(), resident.end(), [](unsigned char r) { return (r & 1) != 0; });
}

bool drop_from_page_cache(const std::string& file) {
  const int fd = ::open(file.c_str(), O_RDONLY);
  if (fd < 0) return false;
  const bool dropped = ::fdatasync(fd) == 0 && ::posix_fadvise(fd, 0, 0, POSIX_FADV_DONTNEED) == 0;
  ::close(fd);
  return dropped;
}

int64_t cancelled_write_bytes() {
  std::ifstream in("/proc/self/io");
  for (std::string key; in >> key;) {
    int64_t value = 0;
    if (!(in >> value)) break;
    if (key == "cancelled_write_bytes:") return value;
  }
  return -1;
}

}  // namespace isotope::testing
