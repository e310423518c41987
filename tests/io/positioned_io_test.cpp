// Reading and writing a whole buffer at a file offset (pread_all, pwrite_all): the bytes are the
// file's whatever the buffer's place in its page, including where the transfer goes through the
// bounce buffer (a destination a few bytes ahead of its source modulo 4 KB), in pieces, to the
// file's end, and on failure.
#include "io/file/positioned_io.h"

#include <fcntl.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdint>
#include <cstdlib>
#include <memory>
#include <string>
#include <vector>

#include "tests/support/temp_dir_test.h"

namespace isotope {
namespace {

namespace pd = positioned_detail;

// Bytes no two offsets share the pattern of (so a piece read from the wrong place shows).
std::vector<unsigned char> pattern(size_t n, uint64_t seed) {
  std::vector<unsigned char> out(n);
  uint64_t x = seed;
  for (size_t i = 0; i < n; ++i) {
    x = x * 6364136223846793005ull + 1442695040888963407ull;
    out[i] = static_cast<unsigned char>(x >> 56);
  }
  return out;
}

// A page-aligned buffer of BYTES and two pages more (in whole pages, as aligned_alloc wants), whose
// usable start lies SHIFT bytes into it.
struct Shifted {
  Shifted(size_t bytes, size_t shift)
      : base(static_cast<unsigned char*>(std::aligned_alloc(pd::kPage, (bytes / pd::kPage + 3) * pd::kPage))),
        at(base.get() + shift) {}
  struct Free {
    void operator()(unsigned char* p) const { std::free(p); }
  };
  std::unique_ptr<unsigned char, Free> base;
  unsigned char* at;
};

class PositionedIo : public testing::TempDirTest {
 protected:
  std::string write_file(const std::vector<unsigned char>& bytes) {
    const std::string path = (dir_ / "data.bin").string();
    const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    EXPECT_GE(fd, 0);
    EXPECT_EQ(::write(fd, bytes.data(), bytes.size()), static_cast<ssize_t>(bytes.size()));
    ::close(fd);
    return path;
  }
};

// The case the bounce buffer is for: the destination 1 to 63 bytes ahead of the source modulo a
// page (a read: the buffer ahead of the file's offset; a write: the file's offset ahead of the
// buffer), never at an equal offset or farther.
TEST(SlowCopy, IsADestinationAFewBytesAheadOfItsSourceModuloAPage) {
  EXPECT_TRUE(pd::slow_copy(16, 0));
  EXPECT_TRUE(pd::slow_copy(1, 0));
  EXPECT_TRUE(pd::slow_copy(63, 0));
  EXPECT_TRUE(pd::slow_copy(3 * 4096 + 208 + 48, 208));
  EXPECT_TRUE(pd::slow_copy(0, 4080));  // a write from a buffer 16 bytes before a page's end
  EXPECT_FALSE(pd::slow_copy(0, 0));
  EXPECT_FALSE(pd::slow_copy(4096 * 5, 4096 * 2));
  EXPECT_FALSE(pd::slow_copy(64, 0));
  EXPECT_FALSE(pd::slow_copy(2048, 0));
  EXPECT_FALSE(pd::slow_copy(4080, 0));  // behind the source
}

TEST_F(PositionedIo, ReadsTheFilesBytesAtEveryPlaceOfTheBufferInItsPage) {
  const std::vector<unsigned char> file = pattern((size_t{3} << 20) + 777, 1);
  const std::string path = write_file(file);
  const int fd = ::open(path.c_str(), O_RDONLY);
  ASSERT_GE(fd, 0);
  // Sizes within one bounce piece, across several, and below the bounce's threshold.
  for (const size_t size : {size_t{100}, size_t{5000}, (size_t{1} << 20) + 3, (size_t{5} << 19)})
    for (const uint64_t offset : {uint64_t{0}, uint64_t{5}, uint64_t{4096}, uint64_t{3 * 4096 + 100}})
      for (const size_t shift : {0, 1, 16, 31, 63, 64, 2048}) {
        Shifted buffer(size, shift + offset % 4096);  // shift: the destination's distance ahead
        const PreadOutcome r = pread_all(fd, buffer.at, size, offset);
        ASSERT_EQ(r.bytes, size) << size << " at " << offset << ", shift " << shift;
        EXPECT_EQ(r.error, 0);
        EXPECT_EQ(std::vector<unsigned char>(buffer.at, buffer.at + size),
                  std::vector<unsigned char>(file.begin() + static_cast<std::ptrdiff_t>(offset),
                                             file.begin() + static_cast<std::ptrdiff_t>(offset + size)))
            << size << " at " << offset << ", shift " << shift;
      }
  ::close(fd);
}

TEST_F(PositionedIo, AReadThroughTheBounceStopsAtTheFilesEndAndLeavesTheRestAlone) {
  const std::vector<unsigned char> file = pattern((size_t{1} << 20) + 4096 + 10, 2);
  const std::string path = write_file(file);
  const int fd = ::open(path.c_str(), O_RDONLY);
  ASSERT_GE(fd, 0);
  const size_t asked = size_t{2} << 20;
  const uint64_t offset = 4096;
  Shifted buffer(asked, 16);
  std::fill(buffer.at, buffer.at + asked, 0xAB);
  const PreadOutcome r = pread_all(fd, buffer.at, asked, offset);
  EXPECT_EQ(r.bytes, file.size() - offset);
  EXPECT_EQ(r.error, 0);
  EXPECT_TRUE(r.ended_early(asked));
  EXPECT_EQ(std::vector<unsigned char>(buffer.at, buffer.at + r.bytes),
            std::vector<unsigned char>(file.begin() + static_cast<std::ptrdiff_t>(offset), file.end()));
  for (size_t i = r.bytes; i < asked; ++i) ASSERT_EQ(buffer.at[i], 0xAB) << i;
  ::close(fd);
}

TEST_F(PositionedIo, AFailedReadOrWriteThroughTheBounceGivesItsError) {
  Shifted buffer(size_t{1} << 20, 16);
  const PreadOutcome r = pread_all(-1, buffer.at, size_t{1} << 20, 0);
  EXPECT_EQ(r.bytes, 0u);
  EXPECT_EQ(r.error, EBADF);
  Shifted from(size_t{1} << 20, 4096 - 16);
  EXPECT_EQ(pwrite_all(-1, from.at, size_t{1} << 20, 0), EBADF);
}

TEST_F(PositionedIo, WritesTheBuffersBytesAtEveryPlaceOfTheBufferInItsPage) {
  const std::string path = (dir_ / "out.bin").string();
  for (const size_t size : {size_t{100}, size_t{5000}, (size_t{5} << 19)})
    for (const uint64_t offset : {uint64_t{0}, uint64_t{208}, uint64_t{4096 + 4000}})
      for (const size_t behind : {0, 1, 16, 48, 63, 64, 2048}) {
        // The buffer BEHIND bytes behind the file's offset modulo a page: the page cache ahead of it.
        const std::vector<unsigned char> bytes = pattern(size, size + offset + behind);
        Shifted buffer(size, (offset + 4096 - behind) % 4096);
        std::copy(bytes.begin(), bytes.end(), buffer.at);
        const int fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_TRUNC, 0644);
        ASSERT_GE(fd, 0);
        ASSERT_EQ(pwrite_all(fd, buffer.at, size, offset), 0);
        std::vector<unsigned char> back(size);
        ASSERT_EQ(::pread(fd, back.data(), size, static_cast<off_t>(offset)), static_cast<ssize_t>(size));
        ::close(fd);
        EXPECT_EQ(back, bytes) << size << " at " << offset << ", behind " << behind;
      }
}

}  // namespace
}  // namespace isotope
