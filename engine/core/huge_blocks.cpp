// The huge-block store behind detail::HugePageAllocator.
#include "engine/core/huge_blocks.h"

#include <sys/mman.h>
#include <sys/resource.h>

#include <algorithm>
#include <array>
#include <cstdint>
#include <cstdlib>
#include <deque>
#include <iterator>
#include <map>
#include <mutex>
#include <new>

#include "engine/core/parallel.h"

namespace isotope::detail {
namespace {

constexpr uintptr_t kHugeMask = kHugePage - 1;

size_t round_to_huge_pages(size_t bytes) { return (bytes + kHugeMask) & ~kHugeMask; }

// BYTES (a multiple of 2 MB) mapped at a 2 MB boundary: one more huge page is mapped, and what lies
// before the boundary and after the block unmapped again.
void* map_aligned(size_t bytes, int flags = 0) {
  const size_t span = bytes + kHugePage;
  void* m = mmap(nullptr, span, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS | flags, -1, 0);
  if (m == MAP_FAILED) return nullptr;
  const auto begin = reinterpret_cast<uintptr_t>(m);
  const uintptr_t first = (begin + kHugeMask) & ~kHugeMask, end = first + bytes;
  if (first > begin) munmap(m, first - begin);
  if (begin + span > end) munmap(reinterpret_cast<void*>(end), begin + span - end);
  advise_huge_pages(reinterpret_cast<void*>(first), bytes);
  return reinterpret_cast<void*>(first);
}

// `live` and `kept` hold std::map nodes, moved between them with extract() and insert(): freeing a
// block allocates nothing (free_huge is noexcept), and taking one allocates only the entry in `live`
// (or in `reserved`, for a reservation).
struct HugeBlocks {
  using Ranges = std::map<uintptr_t, size_t>;  // address -> bytes
  struct Reservation {
    size_t bytes;
    int purpose;
  };
  std::mutex mutex;
  size_t cap = 0;  // bytes of freed blocks kept; 0: malloc's blocks
  Ranges live;     // blocks of the store's own, handed out
  Ranges kept;     // freed ones, neighbours joined
  size_t kept_bytes = 0;
  std::map<uintptr_t, Reservation> reserved;  // address space only (AddressSpaceOnly), handed out
  // Freed reservations with their pages, oldest first, for the next reservations of their purpose.
  std::deque<std::pair<uintptr_t, Reservation>> warm;
  size_t warm_bytes = 0;

  // Keeps a freed reservation warm, the oldest ones given back to make room; or gives it back.
  void keep_warm(uintptr_t p, Reservation r) {
    if (r.bytes > kWarmReservationBytes) {
      munmap(reinterpret_cast<void*>(p), r.bytes);
      return;
    }
    while (warm_bytes + r.bytes > kWarmReservationBytes) give_back_warm();
    try {
      warm.emplace_back(p, r);
      warm_bytes += r.bytes;
    } catch (...) {
      munmap(reinterpret_cast<void*>(p), r.bytes);
    }
  }
  // Whether the huge page at P is mapped (mincore fails with ENOMEM on a hole).
  static bool still_mapped(void* p) noexcept {
    unsigned char resident[kHugePage / 4096];
    return mincore(p, kHugePage, resident) == 0;
  }
  void give_back_warm() noexcept {
    munmap(reinterpret_cast<void*>(warm.front().first), warm.front().second.bytes);
    warm_bytes -= warm.front().second.bytes;
    warm.pop_front();
  }

  // Moves the newest warm reservation of PURPOSE that fits in [at, at + bytes) to AT, replacing
  // the fresh pages there; the warm range is left unmapped. A huge page at a time: a warm range may
  // be several mappings (its first pages moved in from an earlier one), which one mremap moves only
  // on recent kernels, and every boundary between them lies on a huge page. A move that fails
  // leaves the rest fresh. It may have unmapped its target first (mremap does, before it looks at
  // the source); the hole is then mapped again. False when it cannot be (another thread mapped
  // it): the rest of [at, at + bytes) is given back around the hole, and the caller gives it up.
  bool warm_up(uintptr_t at, size_t bytes, int purpose) noexcept {
    for (auto it = warm.rbegin(); it != warm.rend(); ++it) {
      if (it->second.purpose != purpose || it->second.bytes > bytes) continue;
      const auto [from, r] = *it;
      warm.erase(std::next(it).base());
      warm_bytes -= r.bytes;
      for (size_t done = 0; done < r.bytes; done += kHugePage) {
        void* target = reinterpret_cast<void*>(at + done);
        if (mremap(reinterpret_cast<void*>(from + done), kHugePage, kHugePage, MREMAP_MAYMOVE | MREMAP_FIXED, target) !=
            MAP_FAILED)
          continue;
        munmap(reinterpret_cast<void*>(from + done), r.bytes - done);  // the rest stays warm no longer
        if (still_mapped(target)) return true;                         // failed before it unmapped the target
        void* again = mmap(target, kHugePage, PROT_READ | PROT_WRITE,
                           MAP_PRIVATE | MAP_ANONYMOUS | MAP_NORESERVE | MAP_FIXED_NOREPLACE, -1, 0);
        if (again == target) return true;
        if (again != MAP_FAILED) munmap(again, kHugePage);  // a kernel that ignores NOREPLACE
        // Another thread mapped the hole: give back the rest, around it.
        munmap(reinterpret_cast<void*>(at), done);
        munmap(reinterpret_cast<void*>(at + done + kHugePage), bytes - done - kHugePage);
        return false;
      }
      return true;
    }
    return true;
  }

  // The smallest kept range that holds BYTES, its rest kept; 0 if none does.
  uintptr_t take(size_t bytes) {
    auto best = kept.end();
    for (auto it = kept.begin(); it != kept.end(); ++it)
      if (it->second >= bytes && (best == kept.end() || it->second < best->second)) best = it;
    if (best == kept.end()) return 0;
    Ranges::node_type range = kept.extract(best);
    const uintptr_t p = range.key();
    if (range.mapped() > bytes) {
      range.mapped() -= bytes;
      range.key() = p + bytes;
      kept.insert(std::move(range));
    }
    kept_bytes -= bytes;
    return p;
  }

  // Keeps a freed block, joined with the kept ranges it touches.
  void keep(Ranges::node_type block) {
    kept_bytes += block.mapped();
    auto next = kept.lower_bound(block.key());
    if (next != kept.end() && block.key() + block.mapped() == next->first) {
      block.mapped() += next->second;
      next = kept.erase(next);
    }
    if (next != kept.begin()) {
      const auto before = std::prev(next);
      if (before->first + before->second == block.key()) {
        before->second += block.mapped();
        return;
      }
    }
    kept.insert(next, std::move(block));
  }

  // Unmaps the largest kept ranges first until at most KEEP bytes are kept.
  void give_back(size_t keep_at_most) {
    while (kept_bytes > keep_at_most && !kept.empty()) {
      auto largest = kept.begin();
      for (auto it = kept.begin(); it != kept.end(); ++it)
        if (it->second > largest->second) largest = it;
      munmap(reinterpret_cast<void*>(largest->first), largest->second);
      kept_bytes -= largest->second;
      kept.erase(largest);
    }
  }
};

HugeBlocks& huge_blocks() {
  static HugeBlocks* blocks = new HugeBlocks;  // never destroyed: blocks may be freed at exit
  return *blocks;
}

thread_local bool address_space_only = false;
thread_local int reservation_purpose = 0;

// The reservation AdoptReservation offers to this thread's next allocation of its size.
struct Adoption {
  void* offered = nullptr;
  bool taken = false;
};
thread_local Adoption adoption;

// The most a reservation may take: an eighth of the address space the process may map, where a
// limit is set (`ulimit -v` or `-d`, as a cluster's scheduler sets them), so that the reservation,
// which counts against the limit although it costs no memory, leaves the rest of the work room.
size_t address_space_to_spare() {
  size_t spare = SIZE_MAX;
  for (const int resource : {RLIMIT_AS, RLIMIT_DATA}) {
    rlimit limit{};
    if (getrlimit(resource, &limit) == 0 && limit.rlim_cur != RLIM_INFINITY)
      spare = std::min(spare, static_cast<size_t>(limit.rlim_cur / 8));
  }
  return spare;
}

}  // namespace

AddressSpaceOnly::AddressSpaceOnly(int purpose) : was_(address_space_only), was_purpose_(reservation_purpose) {
  address_space_only = true;
  reservation_purpose = purpose;
}
AddressSpaceOnly::~AddressSpaceOnly() {
  address_space_only = was_;
  reservation_purpose = was_purpose_;
}

AdoptReservation::AdoptReservation(void* p) noexcept { adoption = {p, false}; }
AdoptReservation::~AdoptReservation() { adoption = {}; }
bool AdoptReservation::adopted() const noexcept { return adoption.taken; }

void shrink_reservation(void* p, size_t bytes) noexcept {
  const size_t keep = std::max<size_t>(kHugePage, round_to_huge_pages(bytes));
  HugeBlocks& b = huge_blocks();
  const std::lock_guard<std::mutex> lock(b.mutex);
  const auto it = b.reserved.find(reinterpret_cast<uintptr_t>(p));
  if (it == b.reserved.end() || it->second.bytes <= keep) return;
  if (munmap(static_cast<char*>(p) + keep, it->second.bytes - keep) == 0) it->second.bytes = keep;  // else kept whole
}

size_t reserved_huge_block_bytes() noexcept {
  HugeBlocks& b = huge_blocks();
  const std::lock_guard<std::mutex> lock(b.mutex);
  size_t bytes = 0;
  for (const auto& [at, r] : b.reserved) bytes += r.bytes;
  return bytes;
}

size_t warm_reservation_bytes() noexcept {
  HugeBlocks& b = huge_blocks();
  const std::lock_guard<std::mutex> lock(b.mutex);
  return b.warm_bytes;
}

void advise_huge_pages(void* p, size_t bytes) noexcept {
  const auto begin = reinterpret_cast<uintptr_t>(p);
  const uintptr_t first = (begin + kHugeMask) & ~kHugeMask, end = (begin + bytes) & ~kHugeMask;
  if (end > first) madvise(reinterpret_cast<void*>(first), end - first, MADV_HUGEPAGE);
}

void prefault_in_parallel(void* p, size_t bytes) noexcept {
  if (bytes == 0) return;
  // Chunks of one huge page, so that no two tasks split one: a fault of 2 MB, or 512 of 4 KB, each
  // far more than a task costs, and an array of a few MB (a small band's hand-over) is shared
  // among the threads too.
  constexpr uintptr_t kChunk = kHugePage;
  const auto begin = reinterpret_cast<uintptr_t>(p), end = begin + bytes;
  const uintptr_t base = begin & ~(kChunk - 1);
  const auto chunks = static_cast<int64_t>((end - base + kChunk - 1) / kChunk);
  try {
    parallel_for(int64_t{0}, chunks, [&](int64_t c) {
      // madvise takes whole pages: the first chunk starts at the page that holds p
      const uintptr_t from = std::max(begin & ~uintptr_t{4095}, base + static_cast<uintptr_t>(c) * kChunk);
      const uintptr_t to = std::min(end, base + static_cast<uintptr_t>(c + 1) * kChunk);
      madvise(reinterpret_cast<void*>(from), to - from, MADV_POPULATE_WRITE);
      // And each page written once from here, its bytes kept: where the hypervisor maps a page
      // for the process only at its first write (about 5 us a page after the call above, on the
      // reference machine), that write is this task's, on all threads, rather than the caller's,
      // often on one (a vector's zero-fill). Only bytes of the range: the caller's alone.
      for (uintptr_t page = std::max(begin, from); page < to; page = (page & ~uintptr_t{4095}) + 4096)
        __atomic_fetch_or(reinterpret_cast<unsigned char*>(page), 0, __ATOMIC_RELAXED);
    });
  } catch (...) {  // a task that could not start: the write faults its pages in instead
  }
}

void prefault(void* p, size_t bytes) noexcept {
  if (bytes < kPrefaultMinBytes) return;
  const auto begin = reinterpret_cast<uintptr_t>(p) & ~uintptr_t{4095};  // madvise takes whole pages
  madvise(reinterpret_cast<void*>(begin), reinterpret_cast<uintptr_t>(p) + bytes - begin, MADV_POPULATE_WRITE);
}

void* allocate_huge(size_t bytes) {
  const size_t rounded = std::max<size_t>(kHugePage, round_to_huge_pages(bytes));
  HugeBlocks& b = huge_blocks();
  if (adoption.offered != nullptr && !adoption.taken) {
    const std::lock_guard<std::mutex> lock(b.mutex);
    const auto it = b.reserved.find(reinterpret_cast<uintptr_t>(adoption.offered));
    if (it != b.reserved.end() && it->second.bytes == rounded) {
      adoption.taken = true;
      return adoption.offered;
    }
  }
  if (address_space_only) {
    if (rounded > address_space_to_spare()) throw std::bad_alloc();
    void* m = map_aligned(rounded, MAP_NORESERVE);
    if (!m) throw std::bad_alloc();
    const std::lock_guard<std::mutex> lock(b.mutex);
    try {
      b.reserved.emplace(reinterpret_cast<uintptr_t>(m), HugeBlocks::Reservation{rounded, reservation_purpose});
    } catch (...) {
      munmap(m, rounded);
      throw;
    }
    if (!b.warm_up(reinterpret_cast<uintptr_t>(m), rounded, reservation_purpose)) {
      b.reserved.erase(reinterpret_cast<uintptr_t>(m));  // given back by warm_up, around another's mapping
      throw std::bad_alloc();
    }
    return m;
  }
  {
    const std::lock_guard<std::mutex> lock(b.mutex);
    if (b.cap > 0) {
      uintptr_t p = b.take(rounded);
      if (p == 0) {
        void* m = map_aligned(rounded);
        if (!m) {  // the address space or the commit limit: what is kept may be what is missing
          b.give_back(0);
          m = map_aligned(rounded);
        }
        if (!m) throw std::bad_alloc();
        p = reinterpret_cast<uintptr_t>(m);
      }
      try {
        b.live.emplace(p, rounded);
      } catch (...) {
        munmap(reinterpret_cast<void*>(p), rounded);
        throw;
      }
      return reinterpret_cast<void*>(p);
    }
  }
  void* p = std::aligned_alloc(kHugePage, rounded);
  if (!p) throw std::bad_alloc();
  advise_huge_pages(p, rounded);
  return p;
}

void free_huge(void* p) noexcept {
  if (!p) return;
  HugeBlocks& b = huge_blocks();
  {
    const std::lock_guard<std::mutex> lock(b.mutex);
    const auto reserved = b.reserved.find(reinterpret_cast<uintptr_t>(p));
    if (reserved != b.reserved.end()) {
      const HugeBlocks::Reservation r = reserved->second;
      b.reserved.erase(reserved);
      b.keep_warm(reinterpret_cast<uintptr_t>(p), r);
      return;
    }
    const auto it = b.live.find(reinterpret_cast<uintptr_t>(p));
    if (it != b.live.end()) {
      HugeBlocks::Ranges::node_type block = b.live.extract(it);
      if (b.kept_bytes + block.mapped() > b.cap)
        munmap(p, block.mapped());
      else
        b.keep(std::move(block));
      return;
    }
  }
  std::free(p);  // from malloc, before the store kept blocks
}

void keep_freed_huge_blocks(size_t bytes) {
  HugeBlocks& b = huge_blocks();
  const std::lock_guard<std::mutex> lock(b.mutex);
  b.cap = bytes;
  b.give_back(bytes);
}

void give_back_huge_blocks(size_t keep) noexcept {
  HugeBlocks& b = huge_blocks();
  const std::lock_guard<std::mutex> lock(b.mutex);
  while (!b.warm.empty() && b.warm_bytes + b.kept_bytes > keep) b.give_back_warm();
  b.give_back(keep);
}

size_t kept_huge_block_bytes() noexcept {
  HugeBlocks& b = huge_blocks();
  const std::lock_guard<std::mutex> lock(b.mutex);
  return b.kept_bytes;
}

// The mesh's arrays' allocators (isotope/mesh.h), which every user of the library takes from here.
template struct HugePageAllocator<std::array<float, 3>>;
template struct HugePageAllocator<std::array<uint32_t, 3>>;

}  // namespace isotope::detail
