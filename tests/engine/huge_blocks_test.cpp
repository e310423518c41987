// The huge-block store (behind detail::HugePageAllocator): once asked to keep freed blocks,
// it hands a freed block out again where it lay, already faulted in, whole or in part, and keeps
// no more than it was told.
#include "engine/core/huge_blocks.h"

#include <gtest/gtest.h>
#include <sys/mman.h>
#include <sys/resource.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <new>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "io/volume/raw_reader.h"

namespace isotope::detail {
namespace {

constexpr size_t kMB = size_t{1} << 20;

int64_t minor_faults() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return usage.ru_minflt;
}

bool on_huge_page_boundary(const void* p) { return reinterpret_cast<uintptr_t>(p) % kHugePage == 0; }

// Every test starts and ends with nothing kept and malloc's blocks.
class HugeBlocks : public testing::Test {
 protected:
  void SetUp() override {
    keep_freed_huge_blocks(0);
    give_back_huge_blocks(0);
  }
  void TearDown() override {
    keep_freed_huge_blocks(0);
    give_back_huge_blocks(0);
  }

  // A block of `bytes` allocated and freed, so kept, then taken again as pieces of the sizes
  // given, in order, each checked to lie right after the one before, the first at the block's start.
  static std::vector<char*> carve(size_t bytes, std::initializer_list<size_t> sizes) {
    char* block = static_cast<char*>(allocate_huge(bytes));
    free_huge(block);
    std::vector<char*> pieces;
    size_t at = 0;
    for (const size_t size : sizes) {
      pieces.push_back(static_cast<char*>(allocate_huge(size)));
      EXPECT_EQ(pieces.back(), block + at) << "piece " << pieces.size() - 1;
      at += size;
    }
    return pieces;
  }
};

TEST_F(HugeBlocks, AFreedBlockIsHandedOutAgainWhereItLayWithItsPagesFaultedIn) {
  keep_freed_huge_blocks(64 * kMB);
  char* first = static_cast<char*>(allocate_huge(6 * kMB));
  ASSERT_TRUE(on_huge_page_boundary(first));
  const int64_t before_fresh = minor_faults();
  std::memset(first, 1, 6 * kMB);
  const int64_t fresh = minor_faults() - before_fresh;
  free_huge(first);
  EXPECT_EQ(kept_huge_block_bytes(), 6 * kMB);

  char* again = static_cast<char*>(allocate_huge(5 * kMB + 1));  // rounds to the same 6 MB
  EXPECT_EQ(again, first);
  EXPECT_EQ(kept_huge_block_bytes(), 0u);
  const int64_t before_reuse = minor_faults();
  std::memset(again, 2, 6 * kMB);
  EXPECT_EQ(minor_faults() - before_reuse, 0) << "touching 6 MB fresh took " << fresh << " faults";
  free_huge(again);
}

TEST_F(HugeBlocks, ASmallerRequestTakesPartOfAKeptBlockAndFreedNeighboursJoin) {
  keep_freed_huge_blocks(64 * kMB);
  char* block = static_cast<char*>(allocate_huge(8 * kMB));
  free_huge(block);
  char* head = static_cast<char*>(allocate_huge(2 * kMB));
  EXPECT_EQ(head, block);
  EXPECT_EQ(kept_huge_block_bytes(), 6 * kMB);
  char* tail = static_cast<char*>(allocate_huge(6 * kMB));
  EXPECT_EQ(tail, block + 2 * kMB);
  EXPECT_EQ(kept_huge_block_bytes(), 0u);
  free_huge(tail);
  free_huge(head);
  EXPECT_EQ(kept_huge_block_bytes(), 8 * kMB);
  char* whole = static_cast<char*>(allocate_huge(8 * kMB));  // only the joined pieces hold it
  EXPECT_EQ(whole, block);
  free_huge(whole);
}

TEST_F(HugeBlocks, APieceFreedBetweenItsKeptNeighboursJoinsBoth) {
  keep_freed_huge_blocks(64 * kMB);
  const std::vector<char*> pieces = carve(6 * kMB, {2 * kMB, 2 * kMB, 2 * kMB});
  ASSERT_FALSE(HasFailure());
  char *block = pieces[0], *head = pieces[0], *middle = pieces[1], *tail = pieces[2];
  free_huge(head);  // and the tail: 4 MB kept in two pieces, 2 MB apart
  free_huge(tail);
  EXPECT_EQ(kept_huge_block_bytes(), 4 * kMB);
  char* elsewhere = static_cast<char*>(allocate_huge(4 * kMB));
  EXPECT_TRUE(elsewhere < block || elsewhere >= block + 6 * kMB) << "two pieces 2 MB apart held 4 MB";
  EXPECT_EQ(kept_huge_block_bytes(), 4 * kMB);
  free_huge(middle);  // joins the head before it and the tail after it
  EXPECT_EQ(allocate_huge(6 * kMB), block);
  free_huge(block);
  free_huge(elsewhere);
}

TEST_F(HugeBlocks, FreedInAnyOrderThePiecesOfABlockMakeItWholeAgain) {
  keep_freed_huge_blocks(64 * kMB);
  std::vector<char*> pieces = carve(6 * kMB, {2 * kMB, 2 * kMB, 2 * kMB});
  ASSERT_FALSE(HasFailure());
  char* block = pieces[0];
  // The tail first, then the head (joins the one after it: no), then the middle (joins both).
  free_huge(pieces[2]);
  free_huge(pieces[0]);
  free_huge(pieces[1]);
  EXPECT_EQ(kept_huge_block_bytes(), 6 * kMB);
  EXPECT_EQ(allocate_huge(6 * kMB), block);
  free_huge(block);
  // The head first, then the middle (joins the head before it), then the tail.
  for (char*& p : pieces) p = static_cast<char*>(allocate_huge(2 * kMB));
  ASSERT_EQ(pieces[0], block);
  free_huge(pieces[0]);
  free_huge(pieces[1]);
  free_huge(pieces[2]);
  EXPECT_EQ(allocate_huge(6 * kMB), block);
  free_huge(block);
}

TEST_F(HugeBlocks, TheSmallestKeptBlockThatHoldsARequestServesIt) {
  keep_freed_huge_blocks(64 * kMB);
  // Mapped one after the other, the small block lies between the large ones, whichever way the
  // kernel places mappings: the first that fits, from either end, is a large one. The spacers keep
  // freed blocks from joining.
  void* large_one = allocate_huge(8 * kMB);
  void* spacer_one = allocate_huge(2 * kMB);
  void* small = allocate_huge(4 * kMB);
  void* spacer_two = allocate_huge(2 * kMB);
  void* large_two = allocate_huge(8 * kMB);
  free_huge(large_one);
  free_huge(small);
  free_huge(large_two);
  void* taken = allocate_huge(4 * kMB);
  EXPECT_EQ(taken, small);
  EXPECT_EQ(kept_huge_block_bytes(), 16 * kMB);
  free_huge(taken);
  free_huge(spacer_one);
  free_huge(spacer_two);
}

TEST_F(HugeBlocks, NoMoreIsKeptThanAskedAndTheRestGoesBack) {
  keep_freed_huge_blocks(4 * kMB);
  void* big = allocate_huge(8 * kMB);
  free_huge(big);
  EXPECT_EQ(kept_huge_block_bytes(), 0u) << "a block beyond what may be kept is unmapped";
  void* a = allocate_huge(2 * kMB);
  void* b = allocate_huge(2 * kMB);
  free_huge(a);
  free_huge(b);
  EXPECT_EQ(kept_huge_block_bytes(), 4 * kMB);
  give_back_huge_blocks(2 * kMB);
  EXPECT_LE(kept_huge_block_bytes(), 2 * kMB);
  give_back_huge_blocks(0);
  EXPECT_EQ(kept_huge_block_bytes(), 0u);
}

TEST_F(HugeBlocks, ABlockMallocGaveBeforeKeepingIsFreedByMalloc) {
  void* from_malloc = allocate_huge(4 * kMB);
  EXPECT_TRUE(on_huge_page_boundary(from_malloc));
  keep_freed_huge_blocks(64 * kMB);
  free_huge(from_malloc);  // under ASan, a block freed by the wrong hand is an error
  EXPECT_EQ(kept_huge_block_bytes(), 0u);
  keep_freed_huge_blocks(0);
  void* again_malloc = allocate_huge(2 * kMB);
  free_huge(again_malloc);
  EXPECT_EQ(kept_huge_block_bytes(), 0u);
}

TEST_F(HugeBlocks, ABlockOfTheStoreStillInUseWhenKeepingStopsIsUnmappedNotGivenToMalloc) {
  keep_freed_huge_blocks(64 * kMB);
  char* p = static_cast<char*>(allocate_huge(4 * kMB));
  std::memset(p, 1, 4 * kMB);
  keep_freed_huge_blocks(0);
  free_huge(p);  // std::free of a mapping aborts (glibc: "free(): invalid pointer"), as ASan reports
  EXPECT_EQ(kept_huge_block_bytes(), 0u);
}

// The allocator sends arrays of 2 MB and more to the store, smaller ones to malloc, both ways.
TEST_F(HugeBlocks, TheAllocatorSendsLargeArraysThroughTheStoreAndSmallOnesToMalloc) {
  keep_freed_huge_blocks(64 * kMB);
  {
    std::vector<char, HugePageAllocator<char>> large(kHugePage), small(kHugePage - 1);
    EXPECT_TRUE(on_huge_page_boundary(large.data()));
    EXPECT_EQ(kept_huge_block_bytes(), 0u);
  }
  EXPECT_EQ(kept_huge_block_bytes(), kHugePage) << "the large array's block kept, the small one freed by malloc";
}

// A huge array, of any size, starts on a huge page (so at a page, as a direct read or write needs)
// and goes back through the store when it ends, where a kept block is reused.
TEST_F(HugeBlocks, AHugeArrayStartsOnAHugePageAndEndsThroughTheStore) {
  keep_freed_huge_blocks(64 * kMB);
  {
    const HugeArray<float> small = make_huge_array<float>(3);
    const HugeArray<float> large = make_huge_array<float>(kMB / 2 + 1);  // a float past 2 MB
    EXPECT_TRUE(on_huge_page_boundary(small.get()));
    EXPECT_TRUE(on_huge_page_boundary(large.get()));
    EXPECT_EQ(kept_huge_block_bytes(), 0u);
  }
  EXPECT_EQ(kept_huge_block_bytes(), 3 * kHugePage) << "one huge page for the small array, two for the large one";
}

// A reservation of address space only: far larger than the memory it will take, handed out
// however much is kept, never kept itself (though the store would keep a block of its size), and
// refused beyond an eighth of a `ulimit -v`.
TEST_F(HugeBlocks, AReservationIsAddressSpaceOnlyAndNeverKept) {
  keep_freed_huge_blocks(64 * kMB);
  {
    const AddressSpaceOnly reserve;
    std::vector<char, UninitializedHugePageAllocator<char>> terabyte, small;
    terabyte.reserve(size_t{1} << 40);
    small.reserve(8 * kMB);
    EXPECT_TRUE(on_huge_page_boundary(terabyte.data()));
    EXPECT_EQ(reserved_huge_block_bytes(), (size_t{1} << 40) + 8 * kMB);
    small.resize(3 * kMB);
    std::memset(small.data(), 7, small.size());
  }
  EXPECT_EQ(reserved_huge_block_bytes(), 0u);
  EXPECT_EQ(kept_huge_block_bytes(), 0u) << "a reservation is not among the freed blocks kept";
  EXPECT_EQ(warm_reservation_bytes(), 8 * kMB) << "the small one is kept for the next reservation, the terabyte not";
  give_back_huge_blocks(0);
#if !defined(__SANITIZE_ADDRESS__) && !defined(__SANITIZE_THREAD__)  // they map terabytes of their own
  struct Limit {
    rlimit was{};
    Limit() { getrlimit(RLIMIT_AS, &was); }
    ~Limit() { setrlimit(RLIMIT_AS, &was); }
  } limit;
  rlimit limited = limit.was;
  limited.rlim_cur = size_t{64} << 30;
  if (limit.was.rlim_max == RLIM_INFINITY || limit.was.rlim_max >= limited.rlim_cur) {
    ASSERT_EQ(setrlimit(RLIMIT_AS, &limited), 0);
    const AddressSpaceOnly reserve;
    EXPECT_THROW(allocate_huge((size_t{8} << 30) + kHugePage), std::bad_alloc) << "over an eighth of 64 GB";
    void* p = allocate_huge(size_t{7} << 30);
    EXPECT_NE(p, nullptr);
    free_huge(p);
  }
#endif
}

// A reservation filled before its size is known becomes a vector of that size, in place: shrunk to
// the size's huge pages, the rest of its address space given back, and adopted by the vector's
// allocation of exactly that size on this thread only. Freed with the vector.
TEST_F(HugeBlocks, AReservationShrunkIsAdoptedByAVectorOfItsSize) {
  using Array = std::vector<uint32_t, UninitializedHugePageAllocator<uint32_t>>;
  constexpr size_t kCount = (5 * kMB + 123) / sizeof(uint32_t);
  void* room = nullptr;
  {
    const AddressSpaceOnly reserve;
    room = allocate_huge(256 * kMB);
  }
  auto* values = static_cast<uint32_t*>(room);
  for (size_t i = 0; i < kCount; ++i) values[i] = static_cast<uint32_t>(i * 2654435761u);
  shrink_reservation(room, kCount * sizeof(uint32_t));
  EXPECT_EQ(reserved_huge_block_bytes(), 6 * kMB);
  std::vector<unsigned char> resident(1);
  EXPECT_EQ(mincore(static_cast<char*>(room) + 6 * kMB, 4096, resident.data()), -1) << "the tail is still mapped";
  {
    const AdoptReservation offer_not_taken(room);
    Array other;
    other.reserve(kCount / 2);
  }
  {
    Array after_the_offer;  // an offer ends with its scope, taken or not
    after_the_offer.reserve(kCount);
    EXPECT_NE(after_the_offer.data(), room);
  }
  {
    Array array;
    {
      const AdoptReservation adopt(room);
      Array other;
      other.reserve(kCount / 2);  // another size: not adopted
      EXPECT_NE(other.data(), room);
      EXPECT_FALSE(adopt.adopted());
      std::thread([&] {  // another thread: not adopted
        Array elsewhere;
        elsewhere.reserve(kCount);
        EXPECT_NE(elsewhere.data(), room);
      })
          .join();
      array.reserve(kCount);
      EXPECT_TRUE(adopt.adopted());
    }
    ASSERT_EQ(array.data(), room);
    array.resize(kCount);
    for (size_t i = 0; i < kCount; i += 997) ASSERT_EQ(array[i], static_cast<uint32_t>(i * 2654435761u)) << i;
  }
  EXPECT_EQ(reserved_huge_block_bytes(), 0u) << "freed with the vector that adopted it";

  keep_freed_huge_blocks(64 * kMB);  // as a server keeps them: adopted all the same, and not kept after
  {
    const AddressSpaceOnly reserve;
    room = allocate_huge(64 * kMB);
  }
  shrink_reservation(room, 4 * kMB);
  {
    Array array;
    {
      const AdoptReservation adopt(room);
      array.reserve(4 * kMB / sizeof(uint32_t));
    }
    EXPECT_EQ(array.data(), room);
  }
  EXPECT_EQ(kept_huge_block_bytes(), 0u);
  EXPECT_EQ(reserved_huge_block_bytes(), 0u);
}

// A reservation freed is kept with its pages, up to kWarmReservationBytes in all, the oldest given
// back first: the next reservation of the same purpose starts on them, moved to its first bytes
// (what was written there is still there, and writing there again faults nothing in); one of
// another purpose, or too small to hold them, starts on fresh pages.
TEST_F(HugeBlocks, AReservationFreedLeavesItsPagesToTheNextOfItsPurpose) {
  const auto reserve = [](size_t bytes, int purpose) {
    const AddressSpaceOnly only(purpose);
    return static_cast<uint32_t*>(allocate_huge(bytes));
  };
  const auto value = [](size_t i) { return static_cast<uint32_t>(i * 2654435761u); };
  constexpr size_t kFilled = 16 * kMB, kCount = kFilled / sizeof(uint32_t), kLarge = size_t{1} << 32;
  uint32_t* first = reserve(kLarge, 1);
  for (size_t i = 0; i < kCount; ++i) first[i] = value(i);
  shrink_reservation(first, kFilled);
  free_huge(first);
  EXPECT_EQ(warm_reservation_bytes(), kFilled);
  EXPECT_EQ(reserved_huge_block_bytes(), 0u);

  uint32_t* other = reserve(kLarge, 2);
  EXPECT_EQ(other[1], 0u) << "another purpose: fresh pages";
  free_huge(other);  // 4 GB: given back, not kept
  uint32_t* small = reserve(8 * kMB, 1);
  EXPECT_EQ(small[1], 0u) << "too small to hold the kept pages: fresh ones";
  EXPECT_EQ(warm_reservation_bytes(), kFilled);

  uint32_t* second = reserve(kLarge, 1);
  EXPECT_EQ(warm_reservation_bytes(), 0u);
  for (size_t i = 0; i < kCount; i += 4099) ASSERT_EQ(second[i], value(i)) << i;
  const int64_t faults = minor_faults();
  std::memset(second, 1, kFilled);
#if !defined(__SANITIZE_ADDRESS__) && !defined(__SANITIZE_THREAD__)  // whose shadow of the range is fresh
  EXPECT_LT(minor_faults() - faults, 8) << "16 MB written on the pages moved in";
#else
  static_cast<void>(faults);
#endif
  EXPECT_EQ(second[kCount], 0u) << "after them, fresh pages";

  free_huge(small);  // unshrunk, but within the bound: kept
  EXPECT_EQ(warm_reservation_bytes(), 8 * kMB);
  shrink_reservation(second, kFilled);
  free_huge(second);
  EXPECT_EQ(warm_reservation_bytes(), 8 * kMB + kFilled);
  uint32_t* third = reserve(kLarge, 3);
  std::memset(third, 2, 48 * kMB);
  shrink_reservation(third, 48 * kMB);
  free_huge(third);
  EXPECT_EQ(warm_reservation_bytes(), kFilled + 48 * kMB) << "the oldest, the small one, given back to make room";
  give_back_huge_blocks(kFilled + 48 * kMB);
  EXPECT_EQ(warm_reservation_bytes(), kFilled + 48 * kMB);
  give_back_huge_blocks(48 * kMB);
  EXPECT_EQ(warm_reservation_bytes(), 48 * kMB) << "the oldest given back first";
  give_back_huge_blocks(0);
  EXPECT_EQ(warm_reservation_bytes(), 0u);

  // A mesh that grows: its reservation's first pages moved in from the last one, the rest its own
  // (two mappings), all kept when it is freed, and moved to the next one whole.
  uint32_t* grown = reserve(kLarge, 4);
  std::memset(grown, 4, 8 * kMB);
  shrink_reservation(grown, 8 * kMB);
  free_huge(grown);
  grown = reserve(kLarge, 4);
  for (size_t i = 0; i < 2 * kCount; ++i) grown[i] = value(i);
  shrink_reservation(grown, 2 * kFilled);
  free_huge(grown);
  grown = reserve(kLarge, 4);
  for (size_t i = 0; i < 2 * kCount; i += 4099) ASSERT_EQ(grown[i], value(i)) << i;
  free_huge(grown);
  give_back_huge_blocks(0);

  uint32_t* too_large = reserve(kLarge, 1);
  std::memset(too_large, 3, kWarmReservationBytes + kMB);
  shrink_reservation(too_large, kWarmReservationBytes + kMB);
  free_huge(too_large);
  EXPECT_EQ(warm_reservation_bytes(), 0u) << "more than the bound: given back";
}

// The kernel's flags of the mapping that holds P (/proc/self/smaps, VmFlags: " hg" once advised
// for huge pages, " nh" once advised against them); empty where none holds it.
std::string vm_flags_of(const void* p) {
  std::ifstream smaps("/proc/self/smaps");
  const auto at = reinterpret_cast<uintptr_t>(p);
  bool holds = false;
  for (std::string line; std::getline(smaps, line);) {
    uintptr_t begin = 0, end = 0;
    char dash = 0;
    std::istringstream head(line);
    if (head >> std::hex >> begin >> dash >> end && dash == '-') {
      holds = at >= begin && at < end;
    } else if (holds && line.starts_with("VmFlags:")) {
      return line.substr(8) + " ";
    }
  }
  return "";
}

// The large arrays ask for transparent huge pages (docs/METHOD.md, "Fresh memory"), however their
// block comes: from malloc, from the store's own mappings, as a reservation; and so does a volume's
// array read whole from a file, over the huge pages it spans. (Where the kernel has no transparent
// huge pages at all, there is nothing to ask.)
TEST_F(HugeBlocks, LargeArraysAreAdvisedForHugePages) {
  if (!std::filesystem::exists("/sys/kernel/mm/transparent_hugepage/enabled"))
    GTEST_SKIP() << "this kernel has no transparent huge pages";
  auto check = [](const void* p, const char* what) {
    const std::string flags = vm_flags_of(p);
    EXPECT_NE(flags.find(" hg "), std::string::npos) << what << ": VmFlags" << flags;
  };
  void* from_malloc = allocate_huge(6 * kMB);
  check(from_malloc, "a block from malloc");
  free_huge(from_malloc);

  keep_freed_huge_blocks(64 * kMB);
  void* own = allocate_huge(6 * kMB);
  check(own, "a block of the store's own");
  free_huge(own);
  void* again = allocate_huge(4 * kMB);  // a kept block handed out again
  check(again, "a kept block");
  free_huge(again);
  keep_freed_huge_blocks(0);

  {
    const AddressSpaceOnly reserve;
    void* reservation = allocate_huge(64 * kMB);
    check(static_cast<char*>(reservation) + 40 * kMB, "a reservation");
    free_huge(reservation);
  }

  std::vector<float> values;
  detail::resize_prefaulted_in_parallel(values, 4 * kMB);  // 16 MB: whole huge pages inside, wherever malloc put it
  check(values.data() + values.size() / 2, "a volume's values");
}

// The pages a range touches, and only those, are in memory once it is prefaulted, on this thread
// (prefault; 0 below) or on one thread or two (prefault_in_parallel). (Not counted as page faults of a write after: a
// sanitizer's memset touches its shadow memory too.)
TEST(Prefault, TheRangesPagesAndOnlyThoseAreFaultedInForWriting) {
  constexpr size_t kPage = 4096, kBytes = 40 * kMB;
  for (int threads : {0, 1, 2}) {
    SCOPED_TRACE(threads);
    const tbb::global_control limit(tbb::global_control::max_allowed_parallelism,
                                    static_cast<size_t>(std::max(threads, 1)));
    // On 4 KB pages, residency is seen page by page.
    void* m = mmap(nullptr, kBytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    ASSERT_NE(m, MAP_FAILED);
    madvise(m, kBytes, MADV_NOHUGEPAGE);  // even where every mapping gets huge pages by default
    auto* p = static_cast<unsigned char*>(m);
    // From 100 bytes into page 3 to 5 bytes into the page that starts 3 MB before the mapping ends:
    // both partial pages are the range's.
    const size_t from = 3 * kPage + 100, to = kBytes - 3 * kMB + 5;
    if (threads == 0)
      prefault(p + from, to - from);
    else
      prefault_in_parallel(p + from, to - from);
    std::vector<unsigned char> resident(kBytes / kPage);
    ASSERT_EQ(mincore(m, kBytes, resident.data()), 0);
    size_t in = 0, wrong = 0;
    for (size_t page = 0; page < resident.size(); ++page) {
      const bool expected = page >= from / kPage && page <= (to - 1) / kPage;
      in += (resident[page] & 1) != 0;
      wrong += ((resident[page] & 1) != 0) != expected;
    }
    EXPECT_EQ(in, (to - 1) / kPage - from / kPage + 1);
    EXPECT_EQ(wrong, 0u);
    munmap(m, kBytes);
  }
}

// prefault_in_parallel writes every page of the range once from its tasks (so that a caller's
// first write is not the one the hypervisor maps the page for: docs/METHOD.md, "Fresh memory"),
// and keeps every byte: the range may hold data, and its partial pages the caller's neighbours'.
TEST(Prefault, ARangePrefaultedInParallelKeepsItsBytes) {
  constexpr size_t kBytes = 24 * kMB;
  const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 2);
  std::vector<unsigned char> bytes(kBytes);
  for (size_t i = 0; i < kBytes; ++i) bytes[i] = static_cast<unsigned char>(i * 2654435761u >> 13 | 1);
  const std::vector<unsigned char> before = bytes;
  prefault_in_parallel(bytes.data() + 100, kBytes - 200);
  EXPECT_TRUE(bytes == before);
}

// A range under kPrefaultMinBytes is left to fault in as it is written; one of that many bytes is
// faulted in (a call costs several microseconds, which a few pages, or an array in memory malloc
// hands out again, do not repay).
TEST(Prefault, ARangeUnderTheLeastIsLeftToItsWrites) {
  constexpr size_t kPage = 4096, kBytes = 4 * kPrefaultMinBytes;
  void* m = mmap(nullptr, kBytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  ASSERT_NE(m, MAP_FAILED);
  madvise(m, kBytes, MADV_NOHUGEPAGE);
  auto* p = static_cast<unsigned char*>(m);
  auto resident = [&](size_t from, size_t to) {
    std::vector<unsigned char> r(kBytes / kPage);
    EXPECT_EQ(mincore(m, kBytes, r.data()), 0);
    return std::count_if(r.begin() + static_cast<std::ptrdiff_t>(from / kPage),
                         r.begin() + static_cast<std::ptrdiff_t>(to / kPage),
                         [](unsigned char x) { return (x & 1) != 0; });
  };
  prefault(p, kPrefaultMinBytes - kPage);
  EXPECT_EQ(resident(0, kBytes), 0);
  prefault(p + 2 * kPrefaultMinBytes, kPrefaultMinBytes);
  EXPECT_EQ(resident(0, kBytes), static_cast<std::ptrdiff_t>(kPrefaultMinBytes / kPage));
  EXPECT_EQ(resident(2 * kPrefaultMinBytes, 3 * kPrefaultMinBytes),
            static_cast<std::ptrdiff_t>(kPrefaultMinBytes / kPage));
  munmap(m, kBytes);
}

// A full array grown for one more element holds the same elements in twice the room, every page of
// it already in memory, the part no element was copied into included. Not full, it is left as it is.
TEST(Prefault, AFullArrayGrowsToTwiceItsRoomWithEveryNewPageInMemory) {
  constexpr size_t kPage = 4096, kCount = 2 * kMB / sizeof(uint32_t);  // 2 MB: from the huge-block store
  std::vector<uint32_t, UninitializedHugePageAllocator<uint32_t>> v;
  v.reserve(kCount);
  for (size_t i = 0; i < kCount; ++i) v.push_back(static_cast<uint32_t>(i * 7));
  ASSERT_EQ(v.capacity(), kCount);
  grow_prefaulted(v);
  ASSERT_EQ(v.size(), kCount);
  ASSERT_EQ(v.capacity(), 2 * kCount);
  for (size_t i = 0; i < kCount; ++i) ASSERT_EQ(v[i], static_cast<uint32_t>(i * 7)) << i;
  // The 2 MB past the elements: neither copied into nor written yet.
  auto* tail = reinterpret_cast<unsigned char*>(v.data() + kCount);
  ASSERT_EQ(reinterpret_cast<uintptr_t>(tail) % kPage, 0u);
  std::vector<unsigned char> resident(2 * kMB / kPage);
  ASSERT_EQ(mincore(tail, 2 * kMB, resident.data()), 0);
  EXPECT_EQ(std::count_if(resident.begin(), resident.end(), [](unsigned char r) { return (r & 1) != 0; }),
            static_cast<std::ptrdiff_t>(resident.size()));
  const uint32_t* before = v.data();
  v.push_back(1);
  grow_prefaulted(v);
  EXPECT_EQ(v.data(), before);
  EXPECT_EQ(v.capacity(), 2 * kCount);
}

// Resized up, the elements kept and the new ones zero, within the capacity or past it; resized
// down, the first ones kept.
TEST(Prefault, AnArrayResizedPrefaultedKeepsItsElementsAndAddsZeros) {
  std::vector<uint32_t, HugePageAllocator<uint32_t>> v{7, 8, 9};
  resize_prefaulted(v, 2);
  EXPECT_EQ(v, (std::vector<uint32_t, HugePageAllocator<uint32_t>>{7, 8}));
  resize_prefaulted(v, 3);  // within the capacity
  EXPECT_EQ(v, (std::vector<uint32_t, HugePageAllocator<uint32_t>>{7, 8, 0}));
  const size_t large = 3 * kMB / sizeof(uint32_t);  // past it, from the huge-block store
  resize_prefaulted(v, large);
  ASSERT_EQ(v.size(), large);
  EXPECT_EQ(v[0], 7u);
  EXPECT_EQ(v[1], 8u);
  EXPECT_EQ(std::count(v.begin() + 2, v.end(), 0u), static_cast<std::ptrdiff_t>(large - 2));
}

}  // namespace
}  // namespace isotope::detail
