#include "engine/extract/streamed_extract.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <exception>
#include <memory>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <thread>
#include <vector>

#include "engine/core/huge_blocks.h"
#include "engine/core/parallel.h"
#include "engine/core/volume_check.h"
#include "engine/extract/array_source.h"
#include "engine/extract/extract_drivers.h"
#include "engine/extract/finest_extract.h"
#include "engine/extract/process_group.h"
#include "isotope/error.h"

namespace isotope {
namespace {

// What a window aims to hold: sixteen windows on a 256^3 volume, so that reading one overlaps
// marching the others from the start, and each read is of whole layers, in file order. Small,
// since every buffer of the ring is fresh memory, which on 4 KB pages cost more to touch than the
// march that reads it (docs/METHOD.md, "eps = 0 from a file"; the ring is on huge pages since).
constexpr int64_t kWindowBytes = int64_t{4} << 20;
// How often a worker waiting for a window looks at the cancel flag: a cold read of a window may
// take a while.
constexpr auto kCancelPoll = std::chrono::milliseconds(20);
// What the windows held at once may take, unless two windows are larger.
constexpr int64_t kRingBytes = int64_t{1} << 30;

// Cell layers per window: whole slabs (layers of blocks), as many as kWindowBytes holds, at least
// one, no more than the volume has.
int64_t window_layers(const std::array<int64_t, 3>& dims, int64_t slab_layers) {
  const int64_t slab_bytes = dims[0] * dims[1] * static_cast<int64_t>(sizeof(float)) * slab_layers;
  const int64_t volume_slabs = (dims[2] - 1 + slab_layers - 1) / slab_layers;
  return slab_layers * std::clamp<int64_t>(kWindowBytes / slab_bytes, 1, volume_slabs);
}

// Node layers a window's buffer holds: its cell layers and the top node layer.
int64_t window_nodes(const std::array<int64_t, 3>& dims, int64_t layers) { return std::min(layers, dims[2] - 1) + 1; }

// The bytes of a window of `layers` cell layers' values.
int64_t window_bytes(const std::array<int64_t, 3>& dims, int64_t layers) {
  return dims[0] * dims[1] * static_cast<int64_t>(sizeof(float)) * window_nodes(dims, layers);
}

// Windows of the cell layers [first, end) this process marches (all of them, or its share of the
// slabs), filled in order by a reader thread into a ring of buffers. Window w holds the nodes of
// cell layers [first + w * layers, first + (w + 1) * layers), its top node layer included (the
// next window reads it again). A buffer is filled again once every slab of its window was marched.
// Progress: slabs are handed out in increasing order (parallel_for_in_order), so the lowest slab
// not yet marched is in a window already filled, or the next to fill, whose buffer is free.
template <class T>
class LayerRing {
 public:
  // `first` and `layers`: whole slabs.
  LayerRing(const std::function<void(int64_t, int64_t, T*)>& read, const LayerSource& source,
            const ExtractCall& options, int64_t first, int64_t end, int64_t layers, int64_t slab_layers, int64_t held)
      : read_(read), options_(options), first_(first), end_(end), layers_(layers), slab_layers_(slab_layers) {
    const int64_t windows = std::max<int64_t>(0, (end - first + layers - 1) / layers);
    marched_.assign(static_cast<size_t>(windows), 0);
    const auto values = static_cast<size_t>(source.dims[0] * source.dims[1] * window_nodes(source.dims, layers));
    // Written whole by each read before any of it is used: not zero-filled first. Each buffer starts
    // at a page, as a window's first node is in the file whenever the values start at a page: the
    // kernel's copy from the page cache into a buffer a few bytes past its source's place in a page
    // runs several times slower (docs/METHOD.md, "Reading and writing files"). All of them in one
    // block of huge pages, each faulted in by the reader just before its first read: into fresh 4
    // KB pages, the first reads cost several times the rest (docs/METHOD.md, "Fresh memory").
    static_assert(detail::kPageBytes % sizeof(T) == 0, "a whole number of values a page");
    stride_ = (values * sizeof(T) + detail::kPageBytes - 1) / detail::kPageBytes * detail::kPageBytes / sizeof(T);
    held_ = std::min(held, windows);
    if (held_ > 0) block_ = detail::make_huge_array<T>(stride_ * static_cast<size_t>(held_));
    reader_ = std::thread([this] { fill(); });
  }
  ~LayerRing() {
    {
      const std::lock_guard<std::mutex> lock(mutex_);
      if (!error_) error_ = std::make_exception_ptr(std::logic_error("the streamed extraction was abandoned"));
    }
    changed_.notify_all();
    reader_.join();
  }
  LayerRing(const LayerRing&) = delete;
  LayerRing& operator=(const LayerRing&) = delete;

  // The window that holds slab z0..., and its first cell layer.
  int64_t window_of(int64_t z0) const { return (z0 - first_) / layers_; }
  int64_t first_layer(int64_t w) const { return first_ + w * layers_; }

  // Window w's values, once filled. Rethrows what stopped the extraction (a read, a march, a
  // cancellation).
  const T* acquire(int64_t w) {
    std::unique_lock<std::mutex> lock(mutex_);
    while (!changed_.wait_for(lock, kCancelPoll, [&] { return filled_ > w || error_; }))
      if (cancelled()) error_ = std::make_exception_ptr(ExtractionCancelled{});
    if (filled_ <= w) {
      changed_.notify_all();  // the reader too, when the cancellation was seen here
      std::rethrow_exception(error_);
    }
    return buffer(w);
  }
  // One slab of window w is marched.
  void release(int64_t w) {
    {
      const std::lock_guard<std::mutex> lock(mutex_);
      ++marched_[static_cast<size_t>(w)];
    }
    changed_.notify_all();
  }
  // Whether a read failed (not a cancellation). Once the ring is gone or failed.
  bool read_failed() const { return read_failed_; }
  // A slab failed: the reader stops, and every wait rethrows the failure.
  void fail(std::exception_ptr e) {
    {
      const std::lock_guard<std::mutex> lock(mutex_);
      if (!error_) error_ = std::move(e);
    }
    changed_.notify_all();
  }

 private:
  bool cancelled() const { return options_.cancel && options_.cancel->load(std::memory_order_relaxed); }
  int64_t cells_in(int64_t w) const { return std::min(layers_, end_ - first_layer(w)); }
  int64_t slabs_in(int64_t w) const { return (cells_in(w) + slab_layers_ - 1) / slab_layers_; }
  T* buffer(int64_t w) const { return block_.get() + static_cast<size_t>(w % held_) * stride_; }

  void fill() {
    for (int64_t w = 0; w < static_cast<int64_t>(marched_.size()); ++w) {
      {
        std::unique_lock<std::mutex> lock(mutex_);
        changed_.wait(lock, [&] {
          return error_ || w < held_ || marched_[static_cast<size_t>(w - held_)] == slabs_in(w - held_);
        });
        if (error_) return;
      }
      try {
        throw_if_cancelled(options_);
        if (w < held_) detail::prefault(buffer(w), stride_ * sizeof(T));
        read_(first_layer(w), cells_in(w) + 1, buffer(w));
      } catch (const ExtractionCancelled&) {
        fail(std::current_exception());
        return;
      } catch (...) {
        read_failed_ = true;
        fail(std::current_exception());
        return;
      }
      {
        const std::lock_guard<std::mutex> lock(mutex_);
        filled_ = w + 1;
      }
      changed_.notify_all();
    }
  }

  const std::function<void(int64_t, int64_t, T*)>& read_;
  const ExtractCall options_;
  const int64_t first_, end_, layers_, slab_layers_;
  size_t stride_ = 0;  // values from a buffer's start to the next's: whole pages
  int64_t held_ = 0;   // buffers: none where no window is ours
  detail::HugeArray<T> block_;
  std::mutex mutex_;
  std::condition_variable changed_;
  int64_t filled_ = 0;            // windows [0, filled_) are in their buffers
  std::vector<int64_t> marched_;  // per window: its slabs marched
  std::exception_ptr error_;      // what stopped the extraction
  std::atomic<bool> read_failed_{false};
  std::thread reader_;  // last: started once the rest is ready
};

// The layers read again, checked, in order, `layers` at a time: throws what a checked read throws
// first (a value that is not finite, a failed read), or returns when they all read.
void read_checked(const LayerSource& source, const ExtractCall& options, int64_t layers) {
  const std::array<int64_t, 3>& dims = source.dims;
  std::vector<float> window(static_cast<size_t>(dims[0] * dims[1] * layers));
  for (int64_t z = 0; z < dims[2]; z += layers) {
    throw_if_cancelled(options);
    source.read_layers(z, std::min(layers, dims[2] - z), window.data());
  }
}

// Where the layers go and who reads which: one process's share of the slabs, its windows, and
// how many are held at once.
struct StreamPlan {
  traversal::SplitRule rule;
  SlabPlan plan;
  ProcessGroup group;
  ProcessGroup::Share share;
  int64_t first, end, layers, held;
};

// The march over windows of values of type T that READ fills. MARCH_CHECKS: the values were
// read unchecked, and the march checks them (ArrayReader).
template <class T>
Mesh march_windows(const LayerSource& source, const ExtractCall& options, const StreamPlan& s,
                   const std::function<void(int64_t, int64_t, T*)>& read, bool march_checks, ExtractStats* stats) {
  const std::array<int64_t, 3>& dims = source.dims;
  const SlabPlan& plan = s.plan;
  const ProcessGroup& group = s.group;
  // The ring's buffers may be more than one process has memory for: under several processes made
  // where a failure on one stops them all, as reading the volume whole was.
  std::optional<LayerRing<T>> ring;
  const auto make_ring = [&] {
    ring.emplace(read, source, options, s.first, s.end, s.layers, plan.slab_layers, s.held);
  };
  group.step(make_ring);
  std::atomic<int64_t> blocks{0}, cells{0};
  std::atomic<bool> met_non_finite{false};
  // A slab that fails anywhere (its march, or its builder before it) fails the ring, so that no
  // worker and not the reader wait for a window that slab will never release.
  const auto on_failure = [&] { ring->fail(std::current_exception()); };
  const MarchSlab march = [&](int64_t z0, int64_t z1, MeshBuilder& builder) {
    const int64_t w = ring->window_of(z0);
    const T* values = ring->acquire(w);
    throw_if_cancelled(options);
    ArrayReader<T> reader(values, dims, ring->first_layer(w), march_checks);
    try {
      march_finest_layers(reader, s.rule, plan, dims, z0, z1, builder, blocks, cells);
    } catch (const NonFiniteValue&) {
      met_non_finite = true;
      throw;
    }
    ring->release(w);
  };
  if (stats) *stats = ExtractStats{};
  Mesh mesh;
  try {
    mesh = march_finest_share(plan, march, group, s.share, options.keep_shares, blocks, cells, {}, stats, on_failure);
  } catch (...) {
    // Read unchecked, the failure that stopped the march may not be the first a checked read
    // meets: a value that is not finite only the march sees, and the reader, windows ahead, may
    // fail a later read first, or a worker meet a later value first. The layers read again,
    // checked, in order, throw the first; if they all read, the file changed meanwhile (a value
    // met) or the read failed once (the failure stands).
    if (!met_non_finite && !(march_checks && ring->read_failed())) throw;
    const bool non_finite = met_non_finite;
    ring.reset();  // its reader stopped: the layers are read again from this thread alone
    read_checked(source, options, window_nodes(dims, s.layers));
    if (!non_finite) throw;
    throw IoError(
        "the volume held a value that is not finite (NaN or infinite) when read, and none when read again: it "
        "changed meanwhile");
  }
  return mesh;
}

// The march over the values as the file stores them, of type T.
template <class T>
Mesh march_stored(const LayerSource& source, const ExtractCall& options, const StreamPlan& s, ExtractStats* stats) {
  const std::function<void(int64_t, int64_t, T*)> read = [&](int64_t z, int64_t count, T* out) {
    source.read_stored(z, count, reinterpret_cast<unsigned char*>(out));
  };
  return march_windows<T>(source, options, s, read, false, stats);
}

}  // namespace

bool streamed_extract_applies(const std::array<int64_t, 3>& dims, const ExtractOptions& options) {
  return !needs_hierarchy(options) && finest_extract_applies(Lattice::enclosing(dims));
}

int64_t streamed_window_bytes(const std::array<int64_t, 3>& dims) {
  const SlabPlan plan = finest_plan(Lattice::enclosing(dims), dims, 0, {0, 0, 0}, {1, 1, 1});
  return window_bytes(dims, window_layers(dims, plan.slab_layers));
}

Mesh extract_streamed(const LayerSource& source, const ExtractCall& options, ExtractStats* stats) {
  options.validate();
  validate_layout(source.dims, source.spacing, source.origin);
  if (!streamed_extract_applies(source.dims, options))
    throw std::logic_error("a streamed extraction is at full resolution");
  const auto start = std::chrono::steady_clock::now();
  const std::array<int64_t, 3>& dims = source.dims;
  const Lattice lattice = Lattice::enclosing(dims);
  const traversal::SplitRule rule(options, lattice, source.origin, source.spacing);
  const SlabPlan plan = finest_plan(lattice, dims, options.iso, source.origin, source.spacing);
  // Under several processes each streams the layers of its own share of the slabs only. Their
  // costs are their cells, as for a volume in memory, which has no records to tell which blocks
  // are cut (the finest extraction's slab_costs): the same shares.
  const ProcessGroup group(options.distribution);
  std::vector<double> costs(static_cast<size_t>(slab_count(plan)));
  for (size_t s = 0; s < costs.size(); ++s)
    costs[s] = static_cast<double>((dims[0] - 1) * (dims[1] - 1) *
                                   (std::min(static_cast<int64_t>(s + 1) * plan.slab_layers, plan.cell_layers) -
                                    static_cast<int64_t>(s) * plan.slab_layers));
  ProcessGroup::Share share = group.share_of(std::move(costs));
  const int64_t first = static_cast<int64_t>(share.first) * plan.slab_layers;
  const int64_t end = std::min(static_cast<int64_t>(share.last) * plan.slab_layers, plan.cell_layers);
  // Windows of whole slabs, none larger than this process's share.
  const int64_t share_slabs = static_cast<int64_t>(share.last - share.first);
  const int64_t layers =
      std::min(window_layers(dims, plan.slab_layers), plan.slab_layers * std::max<int64_t>(share_slabs, 1));
  const int64_t held = std::max<int64_t>(2, std::min(thread_count() + 1, kRingBytes / window_bytes(dims, layers)));
  // One process reads unchecked when it can, its march checking every value as it looks at it:
  // every node lies in a block's rows when each axis has two nodes (ArrayReader::block_cut). Under
  // several processes each reads checked, as one that met a bad value could not name it alone.
  const bool march_checks =
      source.read_unchecked && !group.spread() && std::ranges::all_of(dims, [](int64_t d) { return d >= 2; });
  const StreamPlan s{rule, plan, group, std::move(share), first, end, layers, held};
  Mesh mesh;
  // Integers as the file stores them, converted in the blocks marched only: a quarter of the
  // bytes of floats for uint8, and no pass converting every value on the reader's thread.
  switch (source.read_stored ? source.stored : ScalarType::float32) {
    case ScalarType::uint8: mesh = march_stored<uint8_t>(source, options, s, stats); break;
    case ScalarType::uint16: mesh = march_stored<uint16_t>(source, options, s, stats); break;
    case ScalarType::int16: mesh = march_stored<int16_t>(source, options, s, stats); break;
    default:
      mesh = march_windows<float>(source, options, s, march_checks ? source.read_unchecked : source.read_layers,
                                  march_checks, stats);
  }
  if (stats) stats->seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return mesh;
}

}  // namespace isotope
