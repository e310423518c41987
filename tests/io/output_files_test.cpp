// The output policy: outputs written atomically (a temporary renamed over the target, never a
// FIFO, a device or an input), their large regions and appends past the page cache with the same
// bytes, and every failed write reported.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <sys/sysmacros.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <map>
#include <stdexcept>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "engine/core/huge_blocks.h"
#include "io/file/atomic_file.h"
#include "io/file/direct_appends.h"
#include "io/file/region_writes.h"
#include "io/file/temporary_registry.h"
#include "isotope/error.h"
#include "tests/support/byte_files.h"
#include "tests/support/io_error_of.h"
#include "tests/support/temp_dir_test.h"
#include "tests/support/test_support.h"

namespace isotope {
namespace {

namespace fs = std::filesystem;

using OutputFiles = testing::TempDirTest;
using testing::io_error_of;
using testing::read_bytes;
using testing::write_bytes;
using testing::write_values;

// ---------------------------------------------------------------- AtomicFile

TEST_F(OutputFiles, AtomicFileDestroyedWithoutCommitLeavesNoFile) {
  const std::string p = path("partial.bin");
  {
    AtomicFile f(p);
    f.write("abc", 3);
    EXPECT_TRUE(fs::exists(f.temp_path()));
    EXPECT_EQ(fs::path(f.temp_path()).parent_path(), dir_);
    EXPECT_FALSE(fs::exists(p));
  }
  EXPECT_TRUE(entries().empty());
}

TEST_F(OutputFiles, AtomicFileCommitReplacesTheTargetAndRemovesTheTemporary) {
  const std::string p = path("done.bin");
  write_values(p, std::vector<uint8_t>{9, 9, 9, 9, 9});
  {
    AtomicFile f(p);
    f.write("xyz", 3);
    EXPECT_EQ(read_bytes(p).size(), 5u);  // the old file stays intact until commit
    f.commit();
    EXPECT_THROW(f.write("more", 4), IoError);
  }
  EXPECT_EQ(read_bytes(p), (std::vector<unsigned char>{'x', 'y', 'z'}));
  EXPECT_EQ(entries(), (std::vector<std::string>{"done.bin"}));
}

// A region appended and then filled on several threads at once, out of order, in blocks that
// straddle no boundary in particular: the file holds the bytes before it, the region's bytes in
// their places, and what was written after it; writing outside the regions made is refused.
TEST_F(OutputFiles, AtomicFileRegionsAreFilledOnSeveralThreadsBetweenOrdinaryWrites) {
  const std::string p = path("regions.bin");
  std::vector<unsigned char> expected{'h', 'e', 'a', 'd'};
  const size_t n = 1000003;
  {
    AtomicFile f(p);
    f.write("head", 4);
    const uint64_t at = f.append_region(n);
    EXPECT_EQ(at, 4u);
    EXPECT_EQ(f.size(), 4 + n);
    std::vector<unsigned char> bytes(n);
    for (size_t i = 0; i < n; ++i) bytes[i] = static_cast<unsigned char>(i * 7 + i / 251);
    const size_t block = 65537, blocks = (n + block - 1) / block;
    std::vector<std::thread> threads;
    for (size_t t = 0; t < 3; ++t)
      threads.emplace_back([&, t] {
        for (auto b = static_cast<int64_t>(blocks - 1 - t); b >= 0; b -= 3) {  // last block first
          const size_t begin = static_cast<size_t>(b) * block, end = std::min(n, begin + block);
          f.write_region(at + begin, bytes.data() + begin, end - begin);
        }
      });
    for (std::thread& th : threads) th.join();
    EXPECT_CONTAINS(io_error_of([&] { f.write_region(at + n - 1, "xy", 2); }), "past the regions appended");
    f.write("tail", 4);
    expected.insert(expected.end(), bytes.begin(), bytes.end());
    expected.insert(expected.end(), {'t', 'a', 'i', 'l'});
    f.commit();
  }
  EXPECT_EQ(read_bytes(p), expected);
}

// Of each page of the file's first BYTES, whether the page cache holds it (mincore's bit 0): mapped,
// not read, so that looking touches no page.
std::vector<unsigned char> pages_in_cache(const std::string& file, size_t bytes) {
  std::vector<unsigned char> resident((bytes + 4095) / 4096);
  const int fd = ::open(file.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) throw std::runtime_error(file + ": cannot open");
  void* map = ::mmap(nullptr, bytes, PROT_READ, MAP_SHARED, fd, 0);
  ::close(fd);
  if (map == MAP_FAILED) throw std::runtime_error(file + ": cannot map");
  const int looked = ::mincore(map, bytes, resident.data());
  ::munmap(map, bytes);
  if (looked != 0) throw std::runtime_error(file + ": mincore failed");
  return resident;
}

// Why direct writes into DIR would not leave its page cache alone ("" where they do): 64 KB written
// so, then looked for.
std::string no_direct_writes_in(const std::string& dir) {
  const std::string probe = dir + "/probe.bin";
  const int fd = ::open(probe.c_str(), O_WRONLY | O_CREAT | O_DIRECT | O_CLOEXEC, 0644);
  if (fd < 0) return "the file system of " + dir + " takes no O_DIRECT: " + std::strerror(errno);
  const auto block = detail::make_page_aligned<unsigned char>(size_t{64} << 10);
  std::memset(block.get(), 7, size_t{64} << 10);
  const bool written = ::pwrite(fd, block.get(), size_t{64} << 10, 0) == (ssize_t{64} << 10);
  ::close(fd);
  const std::vector<unsigned char> probed = pages_in_cache(probe, size_t{64} << 10);
  std::filesystem::remove(probe);
  if (!written || std::any_of(probed.begin(), probed.end(), [](unsigned char r) { return (r & 1) != 0; }))
    return "the file system of " + dir + " takes no direct write past its page cache";
  return "";
}

// A large region's whole pages go past the page cache (O_DIRECT) and its partial pages through it,
// whether a piece is copied from the caller's bytes (write_region) or encoded in place
// (fill_region): filled on several threads, out of order, in pieces of odd sizes at odd offsets
// (large ones, ones of about 64 KB whose whole pages may or may not be enough for a direct write,
// small ones), the file holds every byte in its place, and where the file system takes direct
// writes, most of its pages are not in the page cache once it is finished (the direct writes never
// put them there). A piece larger than fill_region takes is refused.
TEST_F(OutputFiles, AtomicFileLargeRegionsGoPastThePageCacheWithTheSameBytes) {
  const size_t n = (size_t{9} << 20) + 4099;
  std::vector<unsigned char> bytes(n);
  for (size_t i = 0; i < n; ++i) bytes[i] = static_cast<unsigned char>(i * 11 + i / 4091);
  // [begin, end): at most one region piece each for fill_region; write_region's first is more
  // than two (copied into the writer's buffers a piece at a time).
  std::vector<std::pair<size_t, size_t>> pieces[2];
  for (const bool fill : {false, true})
    for (size_t at = 0, k = 0; at < n; ++k) {
      const size_t most = k == 0 && !fill ? 2 * AtomicFile::kRegionPieceBytes + 12345 : AtomicFile::kRegionPieceBytes;
      const size_t length = std::min({n - at, most - k % 2,
                                      k % 4 == 0   ? most - k
                                      : k % 4 == 1 ? 852001 + 37 * k
                                      : k % 4 == 2 ? 70001 - 7 * k
                                                   : 1000 + k});
      pieces[fill].emplace_back(at, at + length);
      at += length;
    }
  std::vector<unsigned char> expected{'h', 'e', 'a', 'd', 'e', 'r'};  // the region starts 6 bytes into a page
  expected.insert(expected.end(), bytes.begin(), bytes.end());
  expected.insert(expected.end(), {'t', 'a', 'i', 'l'});
  const std::string no_direct = no_direct_writes_in(dir_.string());
  for (const bool fill : {false, true}) {
    SCOPED_TRACE(fill ? "fill_region" : "write_region");
    const std::string p = path(fill ? "filled_regions.bin" : "large_regions.bin");
    std::vector<unsigned char> resident;
    {
      AtomicFile f(p);
      f.write("header", 6);
      const uint64_t at = f.append_region(n);
      std::atomic<size_t> taken{0};
      std::vector<std::thread> threads;
      for (int t = 0; t < 3; ++t)
        threads.emplace_back([&] {
          for (size_t i; (i = taken++) < pieces[fill].size();) {
            const auto [begin, end] = pieces[fill][pieces[fill].size() - 1 - i];  // the last piece first
            if (fill)
              f.fill_region(at + begin, end - begin, [&, begin = begin, end = end](unsigned char* out) {
                std::copy(bytes.begin() + static_cast<std::ptrdiff_t>(begin),
                          bytes.begin() + static_cast<std::ptrdiff_t>(end), out);
              });
            else
              f.write_region(at + begin, bytes.data() + begin, end - begin);
          }
        });
      for (std::thread& th : threads) th.join();
      if (fill) {
        EXPECT_THROW(f.fill_region(at, AtomicFile::kRegionPieceBytes + 1, [](unsigned char*) {}), std::logic_error);
      }
      f.write("tail", 4);
      f.finish();
      resident = pages_in_cache(f.temp_path(), 6 + n + 4);
      f.commit();
    }
    EXPECT_TRUE(read_bytes(p) == expected) << p << " differs from the bytes written";
    if (!no_direct.empty()) continue;
    const auto cached = std::count_if(resident.begin(), resident.end(), [](unsigned char r) { return (r & 1) != 0; });
    EXPECT_LT(cached, static_cast<std::ptrdiff_t>(resident.size() / 10)) << "of " << resident.size() << " pages";
  }
  if (!no_direct.empty()) GTEST_SKIP() << no_direct;
}

// Direct appends (DirectAppends) write the bytes they were given, past the page cache
// or through it: pieces of odd sizes across several of its buffers, overwrites of bytes on disk,
// in the buffer being filled and across the two, and appends after a drain, from an aligned
// offset and from an unaligned one.
TEST_F(OutputFiles, DirectAppendsWriteWhatTheyWereGivenWithOrWithoutThePageCache) {
  for (const bool direct : {false, true}) {
    for (const size_t total : {size_t{3} << 20, (size_t{3} << 20) + 4099}) {
      SCOPED_TRACE(std::string(direct ? "direct" : "buffered") + ", " + std::to_string(total) + " bytes");
      const std::string p = path("appends.bin");
      const int buffered = ::open(p.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
      ASSERT_GE(buffered, 0);
      const int fd = direct ? ::open(p.c_str(), O_WRONLY | O_DIRECT | O_CLOEXEC) : -1;
      if (direct && fd < 0) {
        ::close(buffered);
        GTEST_SKIP() << "the file system of " << dir_ << " takes no O_DIRECT: " << std::strerror(errno);
      }
      std::vector<unsigned char> expected(total);
      for (size_t i = 0; i < total; ++i) expected[i] = static_cast<unsigned char>(i * 13 + i / 4093);
      {
        DirectAppends appends(fd, buffered);
        const size_t half = total / 2;
        for (size_t at = 0, piece = 1; at < half; at += piece, piece = piece * 3 % 70001 + 1)
          ASSERT_EQ(appends.append(expected.data() + at, std::min(piece, half - at)), 0);
        ASSERT_EQ(appends.drain(), 0);  // the second half starts aligned at 3 MiB, unaligned at 3 MiB + 4099
        for (size_t at = half, piece = 7; at < total; at += piece, piece = piece * 5 % 300007 + 1)
          ASSERT_EQ(appends.append(expected.data() + at, std::min(piece, total - at)), 0);
        EXPECT_EQ(appends.size(), total);
        const std::vector<std::pair<size_t, size_t>> patches{
            {0, 1000}, {(size_t{1} << 20) - 10, 20}, {total - 5000, 4000}, {total - 3, 3}, {(size_t{2} << 20) - 1, 2}};
        for (const auto& [at, bytes] : patches) {
          for (size_t i = at; i < at + bytes; ++i) expected[i] = static_cast<unsigned char>(~expected[i]);
          ASSERT_EQ(appends.overwrite(at, expected.data() + at, bytes), 0);
        }
        ASSERT_EQ(appends.drain(), 0);
        EXPECT_EQ(appends.direct(), direct);
      }
      if (fd >= 0) ::close(fd);
      ::close(buffered);
      EXPECT_EQ(read_bytes(p), expected);
    }
  }
}

// Appends MEGABYTES of 1 MB each, then drains: the first error either met, or 0.
int append_and_drain(DirectAppends& appends, int megabytes) {
  const std::vector<unsigned char> bytes(size_t{1} << 20, 7);
  int err = 0;
  for (int i = 0; i < megabytes && err == 0; ++i) err = appends.append(bytes.data(), bytes.size());
  return err != 0 ? err : appends.drain();
}

// A write the writer thread fails (here: a descriptor not open for writing) is reported by the
// append or the drain after it, with its errno.
TEST_F(OutputFiles, DirectAppendsReportAFailedWriteByTheirWriterThread) {
  const std::string p = path("refused.bin");
  write_values(p, std::vector<uint8_t>{1});
  const int read_only = ::open(p.c_str(), O_RDONLY | O_CLOEXEC);
  ASSERT_GE(read_only, 0);
  {
    DirectAppends appends(-1, read_only);
    EXPECT_EQ(append_and_drain(appends, 3), EBADF);
  }
  ::close(read_only);
}

// A region's writer thread (RegionWrites) writes what it is handed: a write it fails
// (here: a descriptor not open for writing) is reported by the next take() and by drain(), with
// its errno, and what is handed over after it is dropped; a direct write the kernel refuses
// (EINVAL: here bytes not aligned in memory) goes through the page cache with the same bytes, as
// every write after it; a writer destroyed with writes not made drops them.
TEST_F(OutputFiles, RegionWritesReportAFailureAndFallBackWhereDirectWritesAreRefused) {
  constexpr size_t kPiece = size_t{256} << 10;
  const std::string p = path("region_writes.bin");
  write_values(p, std::vector<uint8_t>{1});
  {
    const int read_only = ::open(p.c_str(), O_RDONLY | O_CLOEXEC);
    ASSERT_GE(read_only, 0);
    {
      RegionWrites writes(read_only, read_only, kPiece);
      int err = 0;
      unsigned char* buffer = writes.take(err);
      ASSERT_NE(buffer, nullptr);
      std::memset(buffer, 3, kPiece);
      writes.submit(buffer, buffer, kPiece, 0);
      EXPECT_EQ(writes.drain(), EBADF);
      EXPECT_EQ(writes.take(err), nullptr);
      EXPECT_EQ(err, EBADF);
      EXPECT_EQ(writes.drain(), EBADF) << "reported once only";
    }
    ::close(read_only);
  }
  const int buffered = ::open(p.c_str(), O_WRONLY | O_TRUNC | O_CLOEXEC);
  const int direct = ::open(p.c_str(), O_WRONLY | O_DIRECT | O_CLOEXEC);
  ASSERT_GE(buffered, 0);
  if (direct < 0) {
    ::close(buffered);
    GTEST_SKIP() << "the file system of " << dir_ << " takes no O_DIRECT: " << std::strerror(errno);
  }
  std::vector<unsigned char> expected(3 * kPiece);
  bool refused = false;
  {
    RegionWrites writes(direct, buffered, kPiece);
    for (size_t k = 0; k < 3; ++k) {  // the second from one byte into its buffer: refused direct
      int err = 0;
      unsigned char* buffer = writes.take(err);
      ASSERT_NE(buffer, nullptr) << err;
      unsigned char* from = buffer + (k == 1 ? 1 : 0);
      for (size_t i = 0; i < kPiece; ++i) from[i] = expected[k * kPiece + i] = static_cast<unsigned char>(i * 5 + k);
      writes.submit(buffer, from, kPiece, k * kPiece);
    }
    EXPECT_EQ(writes.drain(), 0);
    refused = !writes.direct();
  }
  EXPECT_TRUE(read_bytes(p) == expected) << p << " differs from the bytes handed over";
  {
    RegionWrites writes(direct, buffered, kPiece);
    for (int k = 0; k < 2; ++k) {
      int err = 0;
      unsigned char* buffer = writes.take(err);
      ASSERT_NE(buffer, nullptr) << err;
      std::memset(buffer, 9, kPiece);
      writes.submit(buffer, buffer, kPiece, (3 + k) * kPiece);
    }
  }  // destroyed without a drain: ends, whatever it wrote of the two
  ::close(direct);
  ::close(buffered);
  EXPECT_TRUE(std::equal(expected.begin(), expected.end(), read_bytes(p).begin()));
  if (!refused) GTEST_SKIP() << "the file system of " << dir_ << " took a direct write from memory one byte off a page";
}

// A region's direct write that fails on the writer thread (here: past a file size limit, EFBIG)
// fails the file's finish() and every commit() after it: the target is never made from a file
// missing those bytes.
TEST_F(OutputFiles, AFailedRegionWriteFailsEveryCommitAfterIt) {
  const std::string p = path("limited.bin");
  const size_t n = size_t{8} << 20, piece = size_t{1} << 20;
  const std::vector<unsigned char> bytes(piece, 5);
  {
    AtomicFile f(p);
    const uint64_t at = f.append_region(n);  // at 0: every piece whole pages, all handed over
    {
      const testing::FileSizeLimit limit(2 << 20);  // writes past 2 MB fail
      try {
        for (size_t k = 0; k < n / piece; ++k) f.write_region(at + k * piece, bytes.data(), piece);
      } catch (const IoError&) {  // a piece handed over after the failure was seen
      }
      EXPECT_CONTAINS(io_error_of([&] { f.finish(); }), "write failed");
    }
    EXPECT_CONTAINS(io_error_of([&] { f.commit(); }), "write failed");
    EXPECT_CONTAINS(io_error_of([&] { f.commit(); }), "write failed");
  }
  EXPECT_FALSE(std::filesystem::exists(p));
  EXPECT_EQ(entries(), std::vector<std::string>{}) << "the temporary is left behind";
}

// Every few MB written, the appends' own thread makes them durable while the caller goes on: a
// large file's commit then waits for its last few MB alone (DirectAppends). Here the
// syncs are seen before any drain: 25 MB appended, at least 16 MB of them synced in time.
TEST_F(OutputFiles, DirectAppendsMakeWhatTheyWroteDurableWhileTheCallerGoesOn) {
  const std::string p = path("synced.bin");
  const int buffered = ::open(p.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  ASSERT_GE(buffered, 0);
  {
    DirectAppends appends(-1, buffered);
    const std::vector<unsigned char> bytes(size_t{1} << 20, 5);
    for (int i = 0; i < 25; ++i) ASSERT_EQ(appends.append(bytes.data(), bytes.size()), 0);
    // A deadline, not a timing: the syncs take milliseconds.
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
    while (appends.synced() < (uint64_t{16} << 20) && std::chrono::steady_clock::now() < deadline)
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    EXPECT_GE(appends.synced(), uint64_t{16} << 20);
    EXPECT_LE(appends.synced(), uint64_t{25} << 20);
    ASSERT_EQ(appends.drain(), 0);
  }
  ::close(buffered);
  EXPECT_EQ(std::filesystem::file_size(p), size_t{25} << 20);
}

// A sync the appends' thread fails (here: /dev/null, which takes writes but no fdatasync) is
// reported by the drain, with its errno: the file's own fsync after it may no longer report it.
TEST_F(OutputFiles, DirectAppendsReportAFailedSyncByTheDrain) {
  const int null = ::open("/dev/null", O_WRONLY | O_CLOEXEC);
  ASSERT_GE(null, 0);
  {
    DirectAppends appends(-1, null);
    EXPECT_EQ(append_and_drain(appends, 12), EINVAL);
  }
  ::close(null);
}

// A store's file takes its appends past the page cache: the same bytes, the same file, as through
// it, with its header written last, and a commit as any other output's.
TEST_F(OutputFiles, AtomicFileWithDirectAppendsHoldsWhatABufferedOneHolds) {
  std::vector<unsigned char> bytes((size_t{5} << 20) + 333);
  for (size_t i = 0; i < bytes.size(); ++i) bytes[i] = static_cast<unsigned char>(i * 31 + i / 509);
  for (const AtomicFile::Appends appends : {AtomicFile::Appends::buffered, AtomicFile::Appends::direct}) {
    const std::string p = path(appends == AtomicFile::Appends::direct ? "direct.bin" : "buffered.bin");
    AtomicFile f(p, appends);
    f.write(bytes.data(), 100);
    for (size_t at = 100; at < bytes.size(); at += 65521)
      f.write(bytes.data() + at, std::min<size_t>(65521, bytes.size() - at));
    f.write_at(0, "header", 6);
    f.commit();
  }
  std::vector<unsigned char> expected = bytes;
  std::memcpy(expected.data(), "header", 6);
  EXPECT_EQ(read_bytes(path("buffered.bin")), expected);
  EXPECT_EQ(read_bytes(path("direct.bin")), expected);
  EXPECT_EQ(entries(), (std::vector<std::string>{"buffered.bin", "direct.bin"}));
}

// What a signal's cleanup removes: registered files, and registered folders with every file in
// them (registered or not) where the folder is still a private one of this user's; never a folder
// registered as a file, nor the files of a folder another mode makes shared, nor what is no longer
// registered.
TEST_F(OutputFiles, TemporariesRemovedAtOnceAreTheRegisteredOnesAndTheFilesOfPrivateFolders) {
  namespace fs = std::filesystem;
  const auto make_folder = [&](const std::string& name, fs::perms mode) {
    const std::string dir = path(name);
    fs::create_directory(dir);
    fs::permissions(dir, mode);
    write_bytes(dir + "/a", "a", 1);
    write_bytes(dir + "/b", "b", 1);
    return dir;
  };
  const std::string mine = make_folder("mine", fs::perms::owner_all);
  const std::string shared =
      make_folder("shared", fs::perms::owner_all | fs::perms::group_read | fs::perms::group_exec);
  const std::string as_file = make_folder("as_file", fs::perms::owner_all);
  const std::string gone = make_folder("gone", fs::perms::owner_all);
  write_bytes(path("file"), "f", 1);
  write_bytes(path("left"), "l", 1);
  const std::vector<int> slots{register_temporary_folder(mine),   register_temporary(mine + "/a"),
                               register_temporary_folder(shared), register_temporary(as_file),
                               register_temporary(path("file")),  register_temporary(path("left")),
                               register_temporary_folder(gone)};
  for (const int slot : slots) ASSERT_GE(slot, 0);
  unregister_temporary(slots[5]);
  unregister_temporary(slots[6]);
  remove_temporaries_now();
  for (const int slot : slots) unregister_temporary(slot);
  EXPECT_FALSE(fs::exists(mine));
  EXPECT_FALSE(fs::exists(path("file")));
  EXPECT_TRUE(fs::exists(shared + "/a") && fs::exists(shared + "/b")) << "a folder not private to this user";
  EXPECT_TRUE(fs::exists(as_file + "/a") && fs::exists(as_file + "/b")) << "registered as a file";
  EXPECT_TRUE(fs::exists(path("left")));
  EXPECT_TRUE(fs::exists(gone + "/a") && fs::exists(gone + "/b"));
}

// A transient file (a volume's hierarchy store, read back and removed by the process that wrote
// it) holds the same bytes and is committed the same way, but is never synced: removed, its pages
// are dropped unwritten, while a kept file's were written to the disk by its commit. (What this
// sees is the file's own sync: a sync of its folder alone writes none of its pages.)
TEST_F(OutputFiles, AtomicFileTransientIsNeverSyncedAndHoldsTheSameBytes) {
  const testing::FolderOnDisk folder("transient");
  std::vector<unsigned char> bytes(size_t{8} << 20);
  for (size_t i = 0; i < bytes.size(); ++i) bytes[i] = static_cast<unsigned char>(i * 13 + i / 4093);
  // Whether the file system says so at all: a file written through the page cache and removed.
  const std::string plain = folder.path() + "/plain.bin";
  write_bytes(plain, bytes.data(), bytes.size());
  const int64_t plain_from = testing::cancelled_write_bytes();
  std::filesystem::remove(plain);
  const int64_t plain_dropped = testing::cancelled_write_bytes() - plain_from;
  if (plain_from < 0 || plain_dropped < static_cast<int64_t>(bytes.size() / 2))
    GTEST_SKIP() << "the file system of " << folder.path() << " does not count the unwritten pages it drops";
  std::map<AtomicFile::Appends, int64_t> dropped;
  for (const AtomicFile::Appends appends : {AtomicFile::Appends::buffered, AtomicFile::Appends::transient}) {
    const std::string p = folder.path() + "/file.bin";
    AtomicFile f(p, appends);
    f.write(bytes.data(), 100);
    f.write(bytes.data() + 100, bytes.size() - 100);
    f.write_at(0, "header", 6);
    f.commit();
    std::vector<unsigned char> expected = bytes;
    std::memcpy(expected.data(), "header", 6);
    EXPECT_EQ(read_bytes(p), expected);
    const int64_t before = testing::cancelled_write_bytes();
    std::filesystem::remove(p);
    dropped[appends] = testing::cancelled_write_bytes() - before;
  }
  EXPECT_TRUE(std::filesystem::is_empty(folder.path()));
  EXPECT_EQ(dropped[AtomicFile::Appends::buffered], 0);
  // Half at least: a writeback that the kernel starts meanwhile may take some of the pages.
  EXPECT_GE(dropped[AtomicFile::Appends::transient], static_cast<int64_t>(bytes.size() / 2))
      << "a plain file dropped " << plain_dropped;
}

// The output policy (AtomicFile): what is not a regular file is never replaced, and
// refused before anything is written.
TEST_F(OutputFiles, AtomicFileRefusesATargetThatIsADirectoryBeforeWriting) {
  fs::create_directory(path("taken"));
  EXPECT_CONTAINS(io_error_of([&] { AtomicFile f(path("taken")); }), "is a directory");
  EXPECT_EQ(entries(), (std::vector<std::string>{"taken"}));
  EXPECT_TRUE(fs::is_directory(path("taken")));
}

TEST_F(OutputFiles, AtomicFileNeverReplacesAFifo) {
  ASSERT_EQ(::mkfifo(path("pipe").c_str(), 0644), 0) << std::strerror(errno);
  EXPECT_CONTAINS(io_error_of([&] { AtomicFile f(path("pipe")); }), "is a FIFO");
  EXPECT_TRUE(fs::is_fifo(path("pipe")));
  EXPECT_EQ(entries(), (std::vector<std::string>{"pipe"}));
}

// A device node made here (as /dev/null is: character device 1,3), never /dev/null itself.
TEST_F(OutputFiles, AtomicFileNeverReplacesADeviceNode) {
  if (::geteuid() != 0) GTEST_SKIP() << "mknod of a device needs root";
  ASSERT_EQ(::mknod(path("null").c_str(), S_IFCHR | 0666, makedev(1, 3)), 0) << std::strerror(errno);
  EXPECT_CONTAINS(io_error_of([&] { AtomicFile f(path("null")); }), "is a character device");
  EXPECT_TRUE(fs::is_character_file(path("null")));
  EXPECT_EQ(entries(), (std::vector<std::string>{"null"}));
}

TEST_F(OutputFiles, AtomicFileFollowsALinkAndReplacesTheFileItNamesInItsOwnDirectory) {
  fs::create_directory(path("real"));
  write_values(path("real/mesh.ply"), std::vector<uint8_t>{1, 2, 3});
  fs::create_symlink("real/mesh.ply", path("link.ply"));  // relative: resolved from the link's folder
  {
    AtomicFile f(path("link.ply"));
    EXPECT_EQ(fs::path(f.temp_path()).parent_path(), fs::path(path("real")));
    f.write("xyz", 3);
    f.commit();
  }
  EXPECT_TRUE(fs::is_symlink(path("link.ply")));
  EXPECT_EQ(read_bytes(path("real/mesh.ply")), (std::vector<unsigned char>{'x', 'y', 'z'}));
  EXPECT_EQ(entries(), (std::vector<std::string>{"link.ply", "real"}));
  EXPECT_TRUE(fs::exists(path("real/mesh.ply")));
  EXPECT_EQ(std::distance(fs::directory_iterator(path("real")), fs::directory_iterator()), 1);

  // A dangling link: the file it names is created. A link to a FIFO: refused. A loop: refused.
  fs::create_symlink(path("real/new.ply"), path("dangling.ply"));
  {
    AtomicFile f(path("dangling.ply"));
    f.write("n", 1);
    f.commit();
  }
  EXPECT_TRUE(fs::is_symlink(path("dangling.ply")));
  EXPECT_EQ(read_bytes(path("real/new.ply")), (std::vector<unsigned char>{'n'}));
  ASSERT_EQ(::mkfifo(path("real/pipe").c_str(), 0644), 0);
  fs::create_symlink("real/pipe", path("to_pipe"));
  EXPECT_CONTAINS(io_error_of([&] { AtomicFile f(path("to_pipe")); }), "a FIFO");
  fs::create_symlink("loop_b", path("loop_a"));
  fs::create_symlink("loop_a", path("loop_b"));
  EXPECT_CONTAINS(io_error_of([&] { AtomicFile f(path("loop_a")); }), "symbolic links");
}

TEST_F(OutputFiles, AnOutputThatIsAnInputOrAnotherOutputIsRefused) {
  write_values(path("in.raw"), std::vector<uint8_t>{1, 2, 3});
  fs::create_hard_link(path("in.raw"), path("hard.raw"));
  fs::create_symlink(path("in.raw"), path("soft.raw"));
  for (const char* same : {"in.raw", "hard.raw", "soft.raw"})
    EXPECT_CONTAINS(io_error_of([&] {
                      check_outputs({{"INPUT", path("in.raw")}}, {{"-o", path(same)}});
                    }),
                    "is the same file as INPUT")
        << same;
  // FILE.h5:/dataset names FILE.h5.
  write_values(path("v.h5"), std::vector<uint8_t>{0});
  EXPECT_CONTAINS(io_error_of([&] {
                    check_outputs({{"INPUT", path("v.h5") + ":/volume"}}, {{"OUTPUT", path("v.h5")}});
                  }),
                  "is the same file as INPUT");
  // Two outputs, existing or not, through a link or not.
  EXPECT_CONTAINS(io_error_of([&] {
                    check_outputs({}, {{"-o", path("m.ply")}, {"--report", path("./m.ply")}});
                  }),
                  "--report " + path("./m.ply") + ": is the same file as -o");
  EXPECT_CONTAINS(io_error_of([&] {
                    check_outputs({}, {{"-o", path("soft.raw")}, {"--report", path("in.raw")}});
                  }),
                  "is the same file as -o");
  // Distinct files pass, and a missing input is left to its reader.
  EXPECT_NO_THROW(check_outputs({{"INPUT", path("in.raw")}, {"INPUT", path("missing.raw")}},
                                {{"-o", path("m.ply")}, {"--report", path("m.json")}, {"--csv", ""}}));
  EXPECT_EQ(read_bytes(path("in.raw")), (std::vector<unsigned char>{1, 2, 3}));
}

}  // namespace
}  // namespace isotope
