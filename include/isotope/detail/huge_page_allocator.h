#pragma once
// Allocator for the engine's large arrays (values, records, meshes): blocks aligned to 2 MB (a huge
// page), advised for transparent huge pages (advise_huge_pages), which a process that repeats its
// work can keep and take again already faulted in. On the reference machine a fresh 4 KB page's
// first touch costs 12-14 us, a fresh huge page's a quarter of that per byte or less, and every
// extraction and convert measured ran as fast or faster on huge pages (docs/METHOD.md, "Fresh
// memory", where an earlier machine measured the other way). Public for the mesh's arrays
// (isotope/mesh.h); what else the engine does with huge blocks (reservations, prefaulting, blocks
// kept for the next run) is the engine's own.

#include <cstddef>
#include <cstdlib>
#include <new>
#include <type_traits>
#include <utility>

namespace isotope::detail {

inline constexpr size_t kHugePage = size_t{2} << 20;

// A block of at least BYTES, aligned to 2 MB and advised for huge pages; throws std::bad_alloc.
// By default from malloc. Once keep_freed_huge_blocks() was called, from mappings of the block
// store's own, outside malloc's heap: a freed block is kept (up to the bytes given) and handed out
// again whole or in part, so a process that repeats the same work (a server answering the same
// request) finds its large arrays where the last run left them, already faulted in, whatever
// smaller allocations came and went in between. In malloc's one heap, a small long-lived allocation
// in the hole a freed array left pushes the next array to fresh pages.
void* allocate_huge(size_t bytes);
void free_huge(void* p) noexcept;  // P from allocate_huge

template <class T>
struct HugePageAllocator {
  using value_type = T;

  HugePageAllocator() = default;
  template <class U>
  HugePageAllocator(const HugePageAllocator<U>&) noexcept {}  // NOLINT: allocators convert implicitly

  T* allocate(size_t n) {
    if (!huge(n)) {
      void* p = std::malloc(n * sizeof(T));
      if (!p) throw std::bad_alloc();
      return static_cast<T*>(p);
    }
    return static_cast<T*>(allocate_huge(n * sizeof(T)));
  }
  void deallocate(T* p, size_t n) noexcept {
    if (huge(n))
      free_huge(p);
    else
      std::free(p);
  }

  template <class U>
  bool operator==(const HugePageAllocator<U>&) const noexcept {
    return true;
  }

 private:
  // Whether n elements come from the huge-block store: allocate and deallocate must agree.
  static bool huge(size_t n) noexcept { return n * sizeof(T) >= kHugePage; }
};

// As HugePageAllocator, but an element made without a value is left unwritten, as `new T` leaves
// it (for the trivial types the mesh holds): resize() then costs neither a pass over the memory nor
// its first touch, so an array written whole right after, by several threads, has each page
// touched by the thread that writes it.
template <class T>
struct UninitializedHugePageAllocator : HugePageAllocator<T> {
  template <class U>
  struct rebind {
    using other = UninitializedHugePageAllocator<U>;
  };
  UninitializedHugePageAllocator() = default;
  template <class U>
  UninitializedHugePageAllocator(const UninitializedHugePageAllocator<U>&) noexcept {}  // NOLINT: as above

  // A trivial element is not even made with `new`: its bytes are what was written there, also
  // before (an array adopted from a reservation, AdoptReservation), which a compiler may take a
  // placement new to end.
  template <class U>
  void construct(U* p) noexcept(std::is_nothrow_default_constructible_v<U>) {
    if constexpr (!std::is_trivially_default_constructible_v<U>) ::new (static_cast<void*>(p)) U;
  }
  template <class U, class... Args>
  void construct(U* p, Args&&... args) {
    ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
  }
};

}  // namespace isotope::detail
