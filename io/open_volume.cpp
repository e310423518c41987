// Any input opened for extraction (isotope/source.h): the one place that assembles the chain
// store -> brick cache -> paged volume, or streams a volume file at eps 0 and otherwise converts it
// into a store of its own, in the temporary directory, on demand. Every
// face (the isotope command's extract, sweep and serve, the C++ API, the bench) opens its input
// here (docs/DESIGN.md, "Seams").
#include <malloc.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <mutex>
#include <optional>
#include <string_view>
#include <utility>

#include "engine/core/huge_blocks.h"
#include "engine/core/parallel.h"
#include "engine/core/volume_check.h"
#include "engine/extract/budget_memo.h"
#include "engine/extract/extract_drivers.h"
#include "engine/extract/options.h"
#include "engine/extract/streamed_extract.h"
#include "engine/hierarchy/hierarchy.h"
#include "engine/hierarchy/lattice.h"
#include "engine/hierarchy/store_layout.h"
#include "io/file/temporary_registry.h"
#include "io/source_access.h"
#include "io/store/brick_cache.h"
#include "io/store/paged_volume.h"
#include "io/store/store_format.h"
#include "io/store/store_reader.h"
#include "io/store/store_writer.h"
#include "io/volume/box_reader.h"
#include "io/volume/raw_reader.h"
#include "io/volume/volume_box_reader.h"
#include "io/volume/volume_reader.h"
#include "isotope/error.h"
#include "isotope/source.h"

namespace isotope {
namespace {

double seconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

void check_cache_mb(const OpenOptions& options) {
  if (options.cache_mb < 1 || options.cache_mb > (int64_t{1} << 30))
    throw OptionError("cache-mb", "must be 1 .. " + std::to_string(int64_t{1} << 30) + " (MB)");
}

// What a store and its cache have read and held, for SourceInfo.
void describe_cache(const StoreReader& store, const BrickCache& cache, int64_t cache_mb, SourceInfo& info) {
  info.store_bytes = store.file_bytes();
  info.cache_mb = cache_mb;
  info.cache_budget_bytes = cache.budget_bytes();
  info.cache_brick_bytes = cache.brick_bytes();
  const BrickCacheStats c = cache.stats();
  info.bytes_read = c.bytes_read;
  info.bricks_read = c.bricks_read;
  info.cache_hits = c.hits;
  info.cache_peak_bytes = c.peak_bytes;
  info.read_waits = c.read_waits;
  info.read_hints = c.read_hints;
}

// A volume's hierarchy as convert makes it, in a store of its own in the temporary directory
// (isotope/source.h), paged like any store: with the sections the first extraction (or the
// extractions prepared) read alone (StoreSections), then, made again, with all.
struct ScratchStore {
  std::unique_ptr<StoreReader> store;
  std::unique_ptr<BrickCache> cache;
  std::unique_ptr<PagedVolume> paged;
  StoreSections sections = kAllSections;
  bool serves(const RecordFields& fields) const {
    const StoreSections needed = sections_for(fields);
    for (size_t s = 0; s < needed.size(); ++s)
      if (needed[s] && !sections[s]) return false;
    return true;
  }
};

}  // namespace

// Its users (the brick cache's decoded bricks, a convert's tiles) free and allocate buffers of a few
// fixed sizes all the time; glibc would return each to the kernel and fault fresh zeroed pages in
// for the next (isotope/source.h).
void keep_freed_memory() {
  mallopt(M_MMAP_THRESHOLD, kKeptBlockBytes);
  mallopt(M_TRIM_THRESHOLD, kKeptTopBytes);
}

struct Source::Impl {
  // A store, paged:
  std::unique_ptr<StoreReader> store;
  std::unique_ptr<BrickCache> cache;
  std::unique_ptr<PagedVolume> paged;
  int64_t cache_mb = 0;
  // Or a volume file (named `path`): read a window of layers at a time by each extraction that
  // streams (eps 0), converted into a scratch store by the first that needs a hierarchy, and read
  // whole only for a triangle budget's count, or where the scratch store could not be written.
  std::unique_ptr<BoxReader> file;
  std::string path;
  // Or a volume held whole (an array, NRRD, or the file once read): set once, never replaced, and
  // published in `held` so that an extraction finds it without a lock.
  mutable std::unique_ptr<Volume> volume;
  mutable std::atomic<const Volume*> held{nullptr};
  // The whole read. Taken inside build_mutex (a hierarchy reads the volume), never around it: an
  // extraction from the volume waits for its read, not for another extraction's hierarchy.
  mutable std::mutex read_mutex;
  mutable std::mutex build_mutex;
  // Shared: an extraction on another thread keeps the hierarchy it started with while a later one
  // that reads more fields builds the next (Source::extract may run on several threads at once).
  mutable std::shared_ptr<const Hierarchy> memory;
  // The hierarchy in a scratch store, which extractions share as they share `memory` (and, as
  // `memory`, made again, with every section, once an extraction reads one it lacks);
  // `memory` is built only where the scratch store could not be written.
  mutable std::shared_ptr<const ScratchStore> scratch;
  mutable bool hierarchy_in_memory = false;  // the scratch store not made, or not made again
  bool tune_allocator = false;
  // The triangle budgets settled so far: the same data whether paged or in memory. Forgotten when
  // the hierarchy is built again, which reads the array again (a borrowed one may have changed).
  mutable BudgetMemo budgets;
  mutable double preprocess_seconds = 0;  // under build_mutex
  mutable double read_seconds = 0;        // under read_mutex

  void hold(std::unique_ptr<Volume> v) const {
    volume = std::move(v);
    held.store(volume.get(), std::memory_order_release);
  }
  const Volume* in_memory() const { return held.load(std::memory_order_acquire); }
  // Whether an extraction with these options streams the file rather than read it whole.
  bool streams(const ExtractCall& options) const {
    return file && !in_memory() && streamed_extract_applies(file->info().dims, options);
  }
  // The options an extraction runs: without the triangle budget when the full-resolution mesh fits
  // it (budget_takes_full_resolution), which a budget reads the volume whole for anyway.
  ExtractCall as_extracted(const ExtractCall& options) const {
    ExtractCall o = options;
    if (options.max_triangles <= 0) return o;
    options.validate();  // before the volume is read
    if (budget_takes_full_resolution(whole(), options)) o.max_triangles = 0;
    return o;
  }
  // The volume, read whole from its file the first time.
  const Volume& whole() const {
    if (const Volume* v = in_memory()) return *v;
    const std::lock_guard<std::mutex> lock(read_mutex);
    if (volume) return *volume;
    const auto start = std::chrono::steady_clock::now();
    const VolumeInfo& i = file->info();
    auto v = std::make_unique<Volume>();
    v->dims = i.dims;
    v->spacing = i.spacing;
    v->origin = i.origin;
    try {
      detail::resize_prefaulted_in_parallel(v->values, static_cast<size_t>(v->node_count()));
    } catch (const std::bad_alloc&) {
      throw IoError(path + ": " + std::to_string(i.dims[0]) + "x" + std::to_string(i.dims[1]) + "x" +
                    std::to_string(i.dims[2]) + " volume does not fit in memory");
    }
    file->read_box({0, 0, 0}, i.dims, v->values.data());
    hold(std::move(v));
    read_seconds += seconds_since(start);
    return *volume;
  }

  // The hierarchy in a store of its own, written once (by the first extraction that needs it) into
  // a folder of its own in the temporary directory, and unlinked with its folder as soon as it is
  // opened. A store, not the hierarchy in memory: the build holds a budget's tiles, not the
  // volume's records (16 bytes a node in memory, 20 GB for a 1024^3 volume), and it is faster, for
  // the same mesh (docs/METHOD.md, "One-shot extraction through a store"). Null, and the hierarchy
  // built in memory as before, where the temporary directory cannot take the store (missing, not
  // writable, full), and for a volume so thin along an axis that a store's bricks would be mostly
  // padding (StoreLayout::memory_brick_bits: the hierarchy in memory takes bricks of 4^3 there).
  // With the sections FIELDS need alone (StoreSections) the first time, with all when made again:
  // a source whose extractions change modes converts its volume twice at most.
  std::shared_ptr<const ScratchStore> paged_hierarchy(const RecordFields& fields, const RunContext& call) const {
    const std::lock_guard<std::mutex> lock(build_mutex);
    if (hierarchy_in_memory || (scratch && scratch->serves(fields))) return scratch;
    const StoreSections sections = scratch ? kAllSections : sections_for(fields);
    // Where no store can be made: the hierarchy in memory, for this extraction and every one after
    // it, which a store of some sections made before would not serve.
    auto in_memory_from_now = [this] {
      hierarchy_in_memory = true;
      scratch.reset();
      return nullptr;
    };
    if (scratch) budgets.clear();  // made again from the volume, as hierarchy() would
    const auto start = std::chrono::steady_clock::now();
    const Volume* held_volume = in_memory();
    const bool thin =
        StoreLayout::memory_brick_bits(held_volume ? held_volume->dims : file->info().dims) != kDefaultBrickBits;
    namespace fs = std::filesystem;
    std::error_code failed;
    const fs::path tmp = fs::temp_directory_path(failed);
    // A folder of this process's own (mode 0700, a name no other process can take): nothing another
    // user placed in a shared temporary directory (a link to a file of ours, a store of the name
    // we would choose) is written through or read.
    std::string folder = (tmp / "isotope-XXXXXX").string();
    if (failed || thin || ::mkdtemp(folder.data()) == nullptr) {
      return in_memory_from_now();
    }
    const std::string name = folder + "/hierarchy.isotope";
    // Removed by the command's handler of SIGINT and SIGTERM as well, should the process be told
    // to end while the store is written (the convert's own temporary name is registered by it).
    const int folder_slot = register_temporary_folder(folder), name_slot = register_temporary(name);
    auto remove_folder = [&] {
      unregister_temporary(name_slot);
      unregister_temporary(folder_slot);
      fs::remove_all(folder, failed);
    };
    ConvertOptions options;
    RunContext run;
    run.progress = call.progress;
    run.cancel = call.cancel;  // a build stopped is the extraction's cancellation (below)
    // Before the build, as `isotope convert` sets it: its tiles' buffers, freed and allocated
    // again tile after tile, then serve the bricks and the mesh from memory already faulted in.
    if (tune_allocator) keep_freed_memory();
    auto built = std::make_shared<ScratchStore>();
    built->sections = sections;
    try {
      if (held_volume) {
        validate_volume(*held_volume);  // a borrowed array may have changed since it was checked
        convert_to_store(VolumeBoxReader(*held_volume), name, ConvertCall(options, run), StoreLife::transient,
                         sections);
      } else {
        convert_to_store(*file, name, ConvertCall(options, run), StoreLife::transient, sections);
      }
      built->store = std::make_unique<StoreReader>(name);
    } catch (const IoError& e) {
      remove_folder();
      // A convert stopped by its cancel flag says "interrupted"; the extraction that asked for the
      // build was cancelled, and says so as every extraction does (RunContext::cancel).
      if (call.cancel && call.cancel->load() && std::string_view(e.what()) == "interrupted")
        throw ExtractionCancelled{};
      // What the store's own files met (a full disk, a file size limit), named in its folder: the
      // hierarchy in memory instead. The input's errors, and whatever stopped the build (a progress
      // callback that throws, as a host's cancel does), are the caller's.
      if (std::string_view(e.what()).find(folder) == std::string_view::npos) throw;
      return in_memory_from_now();
    } catch (...) {
      remove_folder();
      throw;
    }
    remove_folder();  // the reader keeps its descriptor
    built->cache = std::make_unique<BrickCache>(*built->store, static_cast<uint64_t>(cache_mb) << 20);
    built->paged = std::make_unique<PagedVolume>(*built->cache);
    scratch = std::move(built);  // an extraction still reading the one before keeps it
    preprocess_seconds += seconds_since(start);
    return scratch;
  }

  std::shared_ptr<const Hierarchy> hierarchy(const RecordFields& fields, const ProgressCallback& progress) const {
    const std::lock_guard<std::mutex> lock(build_mutex);
    if (memory && memory->fields().covers(fields)) return memory;
    const Volume& values = whole();
    const RecordFields all = memory ? memory->fields() | fields : fields;
    memory.reset();  // freed now unless an extraction still holds it
    budgets.clear();
    const auto start = std::chrono::steady_clock::now();
    memory = std::make_shared<const Hierarchy>(Hierarchy::build(values, all, Hierarchy::kMemoryBrickBits, progress));
    preprocess_seconds += seconds_since(start);
    return memory;
  }
};

Source::Source(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Source::Source(Source&&) noexcept = default;
Source& Source::operator=(Source&&) noexcept = default;
Source::~Source() = default;

Source open_volume(const VolumeSpec& spec, const OpenOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  auto impl = std::make_unique<Source::Impl>();
  check_cache_mb(options);
  impl->cache_mb = options.cache_mb;
  impl->tune_allocator = options.tune_allocator;
  // A store is known by its magic; a file named .isotope without it is a damaged store, whose
  // reader says so, not a raw volume whose name lacks its dimensions (tests/golden/zeros.isotope).
  if (is_store_file(spec.path) || spec.path.ends_with(".isotope")) {
    if (spec.dims || spec.type) throw OptionError(spec.dims ? "dims" : "type", "does not apply to a store");
    if (options.tune_allocator) keep_freed_memory();
    impl->store = std::make_unique<StoreReader>(spec.path);
    impl->cache = std::make_unique<BrickCache>(*impl->store, static_cast<uint64_t>(options.cache_mb) << 20);
    impl->paged = std::make_unique<PagedVolume>(*impl->cache);
  } else if (locate_volume(spec).format == VolumeLocation::Format::nrrd) {
    // gzip-encoded NRRD is read at random only through an inflated copy: read it whole, once.
    impl->hold(std::make_unique<Volume>(read_volume(spec)));
  } else {
    // Checks what needs no value: size, layout, dataset. A chunked HDF5 dataset keeps a layer of
    // its chunks decoded (at most 256 MB, and a layer of the stored volume), so that each window of
    // the one-shot march does not decode again the chunks the window before it cut.
    constexpr uint64_t kChunkCacheBytes = uint64_t{256} << 20;
    impl->file = open_box_reader(spec, "", kChunkCacheBytes);
    impl->path = spec.path;
  }
  impl->read_seconds = seconds_since(start);
  return Source(std::move(impl));
}

Source open_volume(Volume volume, const OpenOptions& options) {
  check_cache_mb(options);  // the cache of the array's hierarchy, in a store of its own
  validate_volume(volume);  // what extract() would refuse, refused at open
  auto impl = std::make_unique<Source::Impl>();
  impl->cache_mb = options.cache_mb;
  impl->tune_allocator = options.tune_allocator;
  impl->hold(std::make_unique<Volume>(std::move(volume)));
  return Source(std::move(impl));
}

Mesh Source::extract(const ExtractOptions& options, const RunContext& run, ExtractStats* stats) const {
  run.validate();
  const ThreadLimit threads(run.threads);
  const ExtractCall call(options, run);
  if (impl_->paged) return isotope::extract(*impl_->paged, call, stats, &impl_->budgets);
  if (impl_->streams(options)) {
    const BoxReader& file = *impl_->file;
    const VolumeInfo& i = file.info();
    LayerSource layers{i.dims, i.spacing, i.origin,
                       [&](int64_t z, int64_t count, float* out) {
                         file.read_box({0, 0, z}, {i.dims[0], i.dims[1], count}, out);
                       },
                       [&](int64_t z, int64_t count, float* out) {
                         file.read_box_unchecked({0, 0, z}, {i.dims[0], i.dims[1], count}, out);
                       }};
    if (const std::optional<ScalarType> stored = file.stored_type()) {
      layers.stored = *stored;
      layers.read_stored = [&](int64_t z, int64_t count, unsigned char* out) {
        file.read_box_stored({0, 0, z}, {i.dims[0], i.dims[1], count}, out);
      };
    }
    return extract_streamed(layers, call, stats);
  }
  const ExtractCall extracted = impl_->as_extracted(call);
  if (!needs_hierarchy(extracted)) {
    // Values read from a file or copied in were checked then; a borrowed array may have changed.
    const Volume& volume = impl_->whole();
    return volume.borrowed.data() ? isotope::extract(volume, extracted, run, stats)
                                  : extract_validated(volume, extracted, stats, run.progress);
  }
  const RecordFields fields = fields_for(extracted);
  if (const std::shared_ptr<const ScratchStore> scratch = impl_->paged_hierarchy(fields, run))
    return isotope::extract(*scratch->paged, extracted, stats, &impl_->budgets);
  const std::shared_ptr<const Hierarchy> hierarchy = impl_->hierarchy(fields, run.progress);
  return isotope::extract(*hierarchy, extracted, stats, &impl_->budgets);
}

void Source::prepare(const std::vector<ExtractOptions>& planned, const RunContext& run) const {
  for (const ExtractOptions& o : planned) o.validate();
  run.validate();
  const ThreadLimit threads(run.threads);
  if (impl_->paged) return;
  RecordFields fields{false, false, false, false};
  bool needed = false, whole = false;
  for (const ExtractOptions& o : planned) {
    const ExtractCall call(o, run);  // as extract() will see it: spread over processes, a budget searches
    fields = fields | fields_for(call);
    const bool hierarchy = needs_hierarchy(impl_->as_extracted(call));
    needed = needed || hierarchy;
    whole = whole || (!hierarchy && !impl_->streams(call));  // eps 0 from the volume held whole
  }
  if (needed && !impl_->paged_hierarchy(fields, run)) impl_->hierarchy(fields, run.progress);  // reads the volume whole
  if (whole) impl_->whole();
}

const StoreReader* detail::SourceAccess::store(const Source& source) { return source.impl_->store.get(); }

SourceInfo Source::info() const {
  const Impl& s = *impl_;
  SourceInfo info;
  if (!s.paged) {
    const std::lock_guard<std::mutex> lock(s.build_mutex);
    {
      const std::lock_guard<std::mutex> read_lock(s.read_mutex);
      info.read_seconds = s.read_seconds;
    }
    if (const Volume* v = s.in_memory()) {
      info.values_in_memory = true;
      info.dims = v->dims;
      info.spacing = v->spacing;
      info.origin = v->origin;
    } else {
      info.dims = s.file->info().dims;
      info.spacing = s.file->info().spacing;
      info.origin = s.file->info().origin;
    }
    info.lattice_k = Lattice::enclosing(info.dims).k;
    info.input_bytes = static_cast<uint64_t>(info.dims[0] * info.dims[1] * info.dims[2]) * sizeof(float);
    info.preprocess_seconds = s.preprocess_seconds;
    info.hierarchy_built = s.memory != nullptr || s.scratch != nullptr;
    if (s.scratch) {
      info.critical_counted = with_topology(s.scratch->sections);
      for (int t = 0; t < 3; ++t) {
        info.critical_paper[t] = s.scratch->store->header().critical_paper[t];
        info.critical_exact[t] = s.scratch->store->header().critical_exact[t];
      }
      describe_cache(*s.scratch->store, *s.scratch->cache, s.cache_mb, info);
    } else if (s.memory) {
      info.critical_counted = s.memory->fields().topology();
      for (int t = 0; t < 3; ++t) {
        info.critical_paper[t] = s.memory->stats().critical_paper[t];
        info.critical_exact[t] = s.memory->stats().critical_exact[t];
      }
    }
    return info;
  }
  // A store was preprocessed by convert; its header keeps the critical-point counts.
  const StoreHeader& h = s.store->header();
  info.store = true;
  info.read_seconds = s.read_seconds;
  info.hierarchy_built = true;
  info.critical_counted = true;
  info.dims = h.dims;
  info.spacing = h.spacing;
  info.origin = h.origin;
  info.lattice_k = s.paged->lattice().k;
  for (int t = 0; t < 3; ++t) {
    info.critical_paper[t] = h.critical_paper[t];
    info.critical_exact[t] = h.critical_exact[t];
  }
  describe_cache(*s.store, *s.cache, s.cache_mb, info);
  return info;
}

}  // namespace isotope
