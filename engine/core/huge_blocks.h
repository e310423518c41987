#pragma once
// The engine's own use of huge blocks (isotope/detail/huge_page_allocator.h, which the mesh's
// arrays share with the public API): reservations filled in place, pages faulted in ahead of their
// writes, blocks kept for a process that repeats its work, and arrays on huge or whole pages.
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <memory>
#include <new>
#include <type_traits>

#include "isotope/detail/huge_page_allocator.h"

namespace isotope::detail {

// A block of at least BYTES, aligned to 2 MB and advised for huge pages; throws std::bad_alloc.
// By default from malloc. Once keep_freed_huge_blocks() was called, from mappings of the block
// store's own, outside malloc's heap: a freed block is kept (up to the bytes given) and handed out
// again whole or in part, so a process that repeats the same work (a server answering the same
// request) finds its large arrays where the last run left them, already faulted in, whatever
// smaller allocations came and went in between. In malloc's one heap, a small long-lived allocation
// in the hole a freed array left pushes the next array to fresh pages.
void* allocate_huge(size_t bytes);
void free_huge(void* p) noexcept;  // P from allocate_huge

// Asks the kernel for transparent huge pages over the whole 2 MB pages inside [p, p + bytes): a
// hint, whose refusal only costs speed (a kernel whose policy is `never` ignores it, one whose
// policy is `always` needs it not).
void advise_huge_pages(void* p, size_t bytes) noexcept;

// Faults in the pages of [p, p + bytes) for writing, on all threads at once, a chunk a task
// (MADV_POPULATE_WRITE): for an array about to be written whole by one thread (a std::vector's
// resize, which zero-fills), whose first touch is the kernel zeroing every page, on one core, and
// costs more than the write itself (docs/METHOD.md, "Fresh memory"). Each page is then written
// once by the tasks, its bytes kept (an atomic or of 0): where a hypervisor maps a page for the
// process only at its first write, that cost too is paid on all threads. A hint: where the kernel
// refuses it, the pages fault in at the write as before.
void prefault_in_parallel(void* p, size_t bytes) noexcept;
// The same on this thread, in one call: for memory about to be written a little at a time (an
// array that grows, blocks handed out one by one), where each page's own fault costs about twice
// its share of one call here (docs/METHOD.md, "Fresh memory"). Pages already there cost a look.
// A range under kPrefaultMinBytes is left to fault in as it is written: the call costs about what
// the faults of so few pages would, and all of it where they are already there, as a small array
// in memory malloc hands out again mostly finds them.
void prefault(void* p, size_t bytes) noexcept;
inline constexpr size_t kPrefaultMinBytes = size_t{64} << 10;

// While one lives, the huge blocks this thread allocates are address space only: mapped without
// the kernel's commit accounting (MAP_NORESERVE), never from malloc nor among the blocks
// keep_freed_huge_blocks() keeps. For an array reserved at a bound far above what it will hold, so
// that it fills in place, without a copy, whatever it comes to: a page costs memory only once
// written. An array that is then written whole runs out of memory at a page fault instead of at its
// allocation: not for arrays sized by what they will hold. A reservation the address space has no
// room for, or larger than an eighth of the process's limit on it (`ulimit -v`, `ulimit -d`), throws
// std::bad_alloc.
//
// A reservation of at most kWarmReservationBytes when freed (shrink_reservation() brings it down)
// is kept, with the pages written in it (the newest ones, up to kWarmReservationBytes in all,
// until give_back_huge_blocks() gives them back). The next reservation of the same PURPOSE (a
// number of the caller's, one per kind of array) starts on them, moved to its first bytes without
// a copy (mremap): a process that repeats an extraction writes its mesh in pages already faulted
// in, as malloc's heap gives a repeated allocation the pages the last one freed. A move that fails
// leaves fresh pages; one that leaves a hole another thread maps first throws std::bad_alloc.
class AddressSpaceOnly {
 public:
  explicit AddressSpaceOnly(int purpose = 0);
  ~AddressSpaceOnly();
  AddressSpaceOnly(const AddressSpaceOnly&) = delete;
  AddressSpaceOnly& operator=(const AddressSpaceOnly&) = delete;

 private:
  bool was_;
  int was_purpose_;
};
inline constexpr size_t kWarmReservationBytes = size_t{64} << 20;
// Bytes of freed reservations kept for the next ones.
size_t warm_reservation_bytes() noexcept;

// Gives back a reservation's address space beyond its first BYTES (rounded up to whole huge pages).
// P: a block allocated under AddressSpaceOnly; anything else is left as it is.
void shrink_reservation(void* p, size_t bytes) noexcept;

// While one lives, the next allocate_huge() on this thread of exactly the bytes P's reservation
// spans (after shrink_reservation) returns P itself, which then belongs to the caller of that
// allocation: so that an array filled in a reservation before its size was known becomes the
// buffer of a vector of that size (HugePageAllocator) without a copy. adopted(): whether it did.
class AdoptReservation {
 public:
  explicit AdoptReservation(void* p) noexcept;
  ~AdoptReservation();
  AdoptReservation(const AdoptReservation&) = delete;
  AdoptReservation& operator=(const AdoptReservation&) = delete;
  bool adopted() const noexcept;
};

// Bytes of address space reserved (AddressSpaceOnly) and not freed yet, in all threads.
size_t reserved_huge_block_bytes() noexcept;

// Keeps up to BYTES of freed huge blocks from now on (0: none, and malloc again for new blocks).
void keep_freed_huge_blocks(size_t bytes);
// Gives kept blocks, and the freed reservations kept for the next ones (AddressSpaceOnly), back to
// the kernel until at most KEEP bytes of both are left, the reservations first.
void give_back_huge_blocks(size_t keep) noexcept;
size_t kept_huge_block_bytes() noexcept;

// Makes room in V for at least one more element, as push_back would (twice the capacity), with
// the new array's pages faulted in by prefault() before the elements are copied into it: a
// growing array's pages, every one first touched by the copy or by the next elements, cost half.
// The last growth faults in pages that may stay unwritten: at most half of that array. (An array
// under kPrefaultMinBytes grows as push_back grows it.)
template <class Vec>
[[gnu::noinline]] void grow_prefaulted_now(Vec& v) {
  using T = typename Vec::value_type;
  Vec bigger;
  bigger.reserve(std::max<size_t>(2 * v.capacity(), size_t{4096} / sizeof(T)));
  prefault(bigger.data(), bigger.capacity() * sizeof(T));
  if constexpr (std::is_same_v<typename Vec::allocator_type, UninitializedHugePageAllocator<T>>) {
    bigger.resize(v.size());  // unwritten: the copy below is one memmove
    std::copy(v.begin(), v.end(), bigger.begin());
  } else {
    bigger.insert(bigger.end(), v.begin(), v.end());
  }
  v.swap(bigger);
}
// The growth out of line: the test is all that every push_back sees.
template <class Vec>
inline void grow_prefaulted(Vec& v) {
  if (v.size() == v.capacity()) [[unlikely]]
    grow_prefaulted_now(v);
}

// V resized to N, the pages of the elements added faulted in at once before they are written (a
// resize that zero-fills them touches every page anyway).
template <class Vec>
void resize_prefaulted(Vec& v, size_t n) {
  if (n <= v.size()) return v.resize(n);
  v.reserve(n);
  prefault(v.data() + v.size(), (n - v.size()) * sizeof(typename Vec::value_type));
  v.resize(n);
}

// V resized to N elements, value-initialized (zero for the trivial types), for an array written
// whole right after: its pages asked for as huge pages and faulted in on all threads before the
// resize's fill, which would take them one at a time on one (a volume's 540 MB of values:
// 0.48-1.2 s -> 0.23-0.44 s on the reference machine; docs/METHOD.md, "Fresh memory"). Throws
// std::bad_alloc.
template <class Vec>
void resize_prefaulted_in_parallel(Vec& v, size_t n) {
  if (n <= v.size()) return v.resize(n);
  v.reserve(n);
  advise_huge_pages(v.data() + v.size(), (n - v.size()) * sizeof(typename Vec::value_type));
  prefault_in_parallel(v.data() + v.size(), (n - v.size()) * sizeof(typename Vec::value_type));
  v.resize(n);
}

// Arrays aligned to a page, not zero-filled (each element is written before it is read): for
// buffers the kernel copies file pages into, where a destination a few bytes past its source's
// place in a page makes that copy several times slower (docs/METHOD.md, "Reading and writing files").
inline constexpr size_t kPageBytes = 4096;
struct FreePageAligned {
  template <class T>
  void operator()(T* p) const {
    ::operator delete[](p, std::align_val_t{kPageBytes});
  }
};
template <class T>
using PageAlignedArray = std::unique_ptr<T[], FreePageAligned>;
template <class T>
PageAlignedArray<T> make_page_aligned(size_t count) {
  return PageAlignedArray<T>(new (std::align_val_t{kPageBytes}) T[count]);
}

// Arrays on huge pages (allocate_huge: at least one, whole ones), aligned to one and not
// zero-filled: for buffers of a MB or more filled again and again (a ring of windows read from a
// file, a writer's buffers), whose first touch on fresh 4 KB pages costs several times what their
// later fills do (docs/METHOD.md, "Fresh memory": 8 MB read from a cached file into fresh 4 KB
// pages 34 ms, into huge pages faulted in first 0.6 + 2.9 ms).
struct FreeHuge {
  template <class T>
  void operator()(T* p) const {
    free_huge(p);
  }
};
template <class T>
using HugeArray = std::unique_ptr<T[], FreeHuge>;
template <class T>
HugeArray<T> make_huge_array(size_t count) {
  static_assert(std::is_trivially_default_constructible_v<T> && std::is_trivially_destructible_v<T>);
  return HugeArray<T>(static_cast<T*>(allocate_huge(count * sizeof(T))));
}

template <class T>
T* HugePageAllocator<T>::allocate(size_t n) {
  if (!huge(n)) {
    void* p = std::malloc(n * sizeof(T));
    if (!p) throw std::bad_alloc();
    return static_cast<T*>(p);
  }
  return static_cast<T*>(allocate_huge(n * sizeof(T)));
}

template <class T>
void HugePageAllocator<T>::deallocate(T* p, size_t n) noexcept {
  if (huge(n))
    free_huge(p);
  else
    std::free(p);
}

}  // namespace isotope::detail
