#pragma once
// An input opened for extraction, whatever it is: a store made by convert is paged through a brick
// cache, so that only the bricks a traversal reaches are read (memory: the cache's budget plus the
// mesh, whatever the store's size). A volume file (raw, HDF5, TIFF) is read by each extraction at
// eps 0 a window of z-layers at a time, marched while the next is read (memory: a few windows plus
// the mesh, so a file larger than memory works). The first extraction that needs its hierarchy
// (eps > 0 or a triangle budget) converts the volume into a store of its own, as convert would,
// in a folder of its own in the system's temporary directory (TMPDIR, else /tmp), unlinked with
// its folder as soon as it is opened (removed too when the build fails or is stopped, and by the
// isotope command when Ctrl-C or SIGTERM ends it meanwhile; a host program killed while the store
// is written leaves that folder, isotope-XXXXXX), and every later one pages it like any store (the store holds
// the sections of its records that the first extraction reads, docs/FORMAT.md "Sections"; the first later
// one that reads another has the volume converted again with all of them): memory within
// convert's budget and the cache's, not the volume's; the cache's statistics, and the store's size,
// in SourceInfo. Only where that directory cannot take the store, or for a volume thinner than a
// brick along an axis, is the hierarchy built in memory instead (16 bytes a node). A triangle budget that the
// full-resolution mesh may fit reads the volume whole to count it, and keeps it. NRRD and an array handed over are held
// in memory from the start. Either way extract() can run many times, from several threads at once, and gives the same
// mesh, byte for byte, for the same volume.
//
//   isotope::Source scan = isotope::open_volume({"scan_512x512x300_uint16.raw"});
//   isotope::ExtractOptions o;
//   o.iso = 1200;
//   o.eps = 4;
//   isotope::write_ply(scan.extract(o), "scan.ply");
#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <isotope/extract.h>
#include <isotope/mesh.h>
#include <isotope/progress.h>
#include <isotope/run_context.h>
#include <isotope/volume.h>

namespace isotope {

namespace detail {
struct SourceAccess;  // the library's own faces' view of a store (defined by the io layer)
}  // namespace detail

// What names an input, as a user types it on the command line.
struct VolumeSpec {
  // A store (`isotope convert`'s output, known by its magic number or the .isotope suffix), a raw
  // file NAME_XxYxZ_TYPE.raw (or any name, with dims and type below), FILE.h5:/path/to/dataset
  // (FILE.h5 alone: its one 3-D dataset), or NRRD (.nrrd, .nhdr).
  std::string path;
  std::optional<std::array<int64_t, 3>> dims;  // raw only: overrides the file name
  std::optional<ScalarType> type;              // raw only: overrides the file name
};

struct OpenOptions {
  // A store, or the store of a volume's hierarchy: memory for decoded bricks (at least 16 bricks); 1 .. 2^30
  int64_t cache_mb = 512;
  // Process-wide: keep freed brick memory for reuse (keep_freed_memory) instead of returning it to
  // the kernel and faulting fresh pages in for the next brick. What the isotope command does; a
  // host program with its own allocator policy leaves it off.
  bool tune_allocator = false;
};

// What OpenOptions::tune_allocator does, and the isotope command's convert: glibc (mallopt) keeps
// freed blocks under kKeptBlockBytes in its heap, and up to kKeptTopBytes free at the heap's top,
// for the next allocations, instead of handing them back to the kernel and faulting fresh zeroed
// pages in for them (docs/METHOD.md, "Fresh memory"). For a process that frees and allocates large
// buffers over and over: the brick cache's bricks, a convert's tiles. The environment variables
// MALLOC_MMAP_THRESHOLD_ and MALLOC_TRIM_THRESHOLD_ set the same for another program (the bench
// runs its peers so).
inline constexpr int kKeptBlockBytes = 64 << 20, kKeptTopBytes = 128 << 20;
void keep_freed_memory();

// What a source is, and what it has read and built so far (for reports).
struct SourceInfo {
  bool store = false;
  std::array<int64_t, 3> dims{0, 0, 0};
  std::array<double, 3> spacing{1, 1, 1};
  std::array<double, 3> origin{0, 0, 0};
  int lattice_k = 0;              // the hierarchy's lattice has 2^k cells per axis
  double read_seconds = 0;        // opening, and reading a volume whole (not its streamed reads)
  double preprocess_seconds = 0;  // a volume: building its hierarchy (its scratch store), so far
  bool hierarchy_built = false;   // a store: always (by convert)
  // A volume: its values held whole in memory (an array, NRRD, or a file once an extraction that
  // does not stream has read it); a file at eps 0 is streamed instead.
  bool values_in_memory = false;
  // Critical points per diamond type (cube, octahedron, diamond): the paper's rule at f(v), and
  // the exact rule for some isovalue. A store's header keeps them; a volume has them once its
  // hierarchy is built with its records' topology, which extractions that read only the range
  // and the error bound (mode none) do without: then critical_counted is false.
  bool critical_counted = false;
  std::array<int64_t, 3> critical_paper{0, 0, 0}, critical_exact{0, 0, 0};
  uint64_t input_bytes = 0;  // a volume: its values as float (what an extraction reads)
  // A store: its size, the cache's budget as asked and in effect, a decoded brick's bytes, and
  // what the cache has read (compressed bytes, bricks), served from memory, and held at most.
  uint64_t store_bytes = 0;
  int64_t cache_mb = 0;
  uint64_t cache_budget_bytes = 0, cache_brick_bytes = 0;
  uint64_t bytes_read = 0;
  int64_t bricks_read = 0, cache_hits = 0;
  uint64_t cache_peak_bytes = 0;
  // A store, since it was opened: its reads that found their bytes missing from the page cache and
  // waited for the disk (every read on a file system that cannot tell), and the read-ahead hints
  // passed to the kernel (none while no read has waited).
  int64_t read_waits = 0, read_hints = 0;
};

class Source {
 public:
  Source(Source&&) noexcept;
  Source& operator=(Source&&) noexcept;
  ~Source();

  // The mesh of the isosurface these options choose. Throws as isotope::extract() does
  // (isotope/extract.h), and IoError when a store's brick or a volume file cannot be read, is
  // corrupt, or holds a value that is not finite. A triangle
  // budget asked for again is the choice this Source made the first time, without the search
  // (ExtractStats::budget_remembered). A volume's budget that its full-resolution mesh fits is
  // that mesh, found by counting, with no hierarchy built.
  // RUN: its threads, its cancel flag, the group of processes it is spread over, and its progress,
  // which hears the build of a volume's hierarchy when this extraction is the one that builds it.
  Mesh extract(const ExtractOptions& options, const RunContext& run = {}, ExtractStats* stats = nullptr) const;
  // Builds now what extractions with these options will need (a volume's hierarchy, with every
  // record field they read), so that a series of them builds it once. A store needs nothing, nor
  // a budget the full-resolution mesh fits (its volume is read). Throws as extract() for options
  // out of range. RUN as for extract(), but for its distribution: every process builds its own.
  void prepare(const std::vector<ExtractOptions>& planned, const RunContext& run = {}) const;
  SourceInfo info() const;

 private:
  struct Impl;
  friend struct detail::SourceAccess;
  friend Source open_volume(const VolumeSpec& spec, const OpenOptions& options);
  friend Source open_volume(Volume volume, const OpenOptions& options);
  explicit Source(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

// Opens what SPEC names: a store's header (its bricks on demand), a volume file's layout (its
// values when an extraction reads them), or a NRRD volume whole. Throws IoError naming the file
// and what is wrong (missing, unreadable, of a size or layout that does not match, not a volume, a
// corrupt store, a version 2 store), and OptionError for dims or type given with a store, or
// cache_mb out of range. A value that is not finite is refused by the extraction that reads it.
Source open_volume(const VolumeSpec& spec, const OpenOptions& options = {});
// An array already in memory (a simulation's field, a numpy array's copy). Throws
// InvalidInput for dimensions below 2, values that do not fill them, or values that are
// not finite.
Source open_volume(Volume volume, const OpenOptions& options = {});

}  // namespace isotope
