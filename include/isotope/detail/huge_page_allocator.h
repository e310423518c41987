#pragma once
// Allocator for the engine's large arrays (values, records, meshes): blocks aligned to 2 MB (a huge
// page), advised for transparent huge pages (advise_huge_pages), which a process that repeats its
// work can keep and take again already faulted in. On the reference machine a fresh 4 KB page's
// first touch costs 12-14 us, a fresh huge page's a quarter of that per byte or less, and every
// extraction and convert measured ran as fast or faster on huge pages (docs/METHOD.md, "Fresh
// memory", where an earlier machine measured the other way). Public for the mesh's arrays
// (isotope/mesh.h), as a declaration: the allocation itself, and what else the engine does with
// huge blocks (reservations, prefaulting, blocks kept for the next run), are the engine's own.

#include <array>
#include <cstddef>
#include <cstdint>
#include <new>
#include <type_traits>
#include <utility>

namespace isotope::detail {

inline constexpr size_t kHugePage = size_t{2} << 20;

template <class T>
struct HugePageAllocator {
  using value_type = T;

  HugePageAllocator() = default;
  template <class U>
  HugePageAllocator(const HugePageAllocator<U>&) noexcept {}  // NOLINT: allocators convert implicitly

  // Defined with the engine's huge-block store: from malloc below
  // a huge page, from the store (allocate_huge) at or above one. The mesh's element types are
  // compiled into the library (below).
  T* allocate(size_t n);
  void deallocate(T* p, size_t n) noexcept;

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

// The mesh's arrays (isotope/mesh.h), allocated by the library's own instances.
extern template struct HugePageAllocator<std::array<float, 3>>;
extern template struct HugePageAllocator<std::array<uint32_t, 3>>;

}  // namespace isotope::detail
