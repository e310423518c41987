#pragma once
// An output file that appears under its name only when complete: written to a temporary
// name in the same directory, renamed by commit(), removed if destroyed before that.
//
// The output policy (every output of isotope goes through here):
// - a new path or an existing regular file is written atomically, as above;
// - a symbolic link is followed, and the file it names is replaced atomically in its own
//   directory (the link stays a link);
// - an existing target that is not a regular file (a device, FIFO, socket or directory) is
//   refused with an IoError before anything is written: it is never replaced;
// - an output that is the same file as an input, or as another output, is refused before any
//   work (check_outputs, which every command calls with what it read and will write).
#include <atomic>
#include <cstdint>
#include <cstdio>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace isotope {

class RegionWrites;

// The file that writing PATH replaces: PATH with every symbolic link followed (a relative link
// resolved from its own directory, at most 40 links). Throws IoError when that file exists and
// is not a regular file, or the links loop.
std::string output_target(const std::string& path);

// A path a command names, with the option or argument that named it (for the message).
struct NamedPath {
  std::string what;  // e.g. "-o", "--report", "INPUT"
  std::string path;
};
// Throws IoError, naming both, when an output is the same file as an input (same device and
// inode, links followed) or two outputs name the same file; also when an output is refused by
// output_target. Inputs that do not exist are left to their readers' messages.
void check_outputs(const std::vector<NamedPath>& inputs, const std::vector<NamedPath>& outputs);

class DirectAppends;

class AtomicFile {
 public:
  // How appends reach the disk: through the page cache, or, for a large output written once from
  // start to end (a store), past it from a writer thread (DirectAppends). Where the
  // file system takes no direct writes, they go through the page cache; the bytes are the same.
  // Transient: through the page cache and never made durable (no fsync of the file or of its
  // directory), for a file this process reads back and removes, whose pages the kernel may then
  // drop unwritten. Errors the writes meet (a full disk, a file size limit) still throw; one that
  // only a writeback would meet (a failing disk) shows, if ever, as a read of the file that fails.
  enum class Appends { buffered, direct, transient };
  // Throws IoError when the directory is not writable.
  explicit AtomicFile(std::string path, Appends appends = Appends::buffered);
  ~AtomicFile();
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;

  void write(const void* data, size_t bytes);  // throws IoError (e.g. disk full)
  // Overwrites bytes already written (a header completed last); the next write() appends.
  void write_at(uint64_t offset, const void* data, size_t bytes);
  // Appends BYTES that write_region() fills, then makes the next write() append after them: a
  // large array encoded and written on several threads at once, each writing its own part (a
  // write on one thread alone held the others back). Returns where the bytes start.
  uint64_t append_region(uint64_t bytes);
  // Writes BYTES at OFFSET inside a region append_region() made. Safe on several threads at once.
  // In a region of at least kDirectRegionBytes, a piece's whole pages are copied into a buffer of
  // the file's writer thread (RegionWrites), which writes them past the page cache
  // (O_DIRECT) while the caller goes on, and the partial pages at its two ends go through the page
  // cache. A piece with fewer than kMinDirectBytes of whole pages, and every piece of a file whose
  // regions have no such thread (none of kDirectRegionBytes yet, a transient file, a file system
  // that refuses O_DIRECT at open) goes all through the page cache, its writeback started at once
  // (not for a transient file). The bytes on disk are the same. A direct write that failed is
  // reported by a later region write or by finish() (by every finish() and commit() after it).
  void write_region(uint64_t offset, const void* data, size_t bytes) const;
  // Writes BYTES at OFFSET inside a region as write_region() does, from what FILL puts at the
  // pointer it is given: in the writer thread's buffer, placed as the file's pages are, so that
  // they are handed over with no copy (records encoded straight into their place). At most
  // kRegionPieceBytes. Safe on several threads.
  void fill_region(uint64_t offset, size_t bytes, const std::function<void(unsigned char*)>& fill) const;
  static constexpr uint64_t kDirectRegionBytes = uint64_t{1} << 20;
  // The most of a piece that goes to the disk in one direct write: a caller that writes a region
  // in pieces of this size pays one request each. Requests of 4 MB moved twice what 1 MB moved
  // (docs/METHOD.md, "Reading and writing files").
  static constexpr size_t kRegionPieceBytes = size_t{4} << 20;
  // Flushes, then makes the next write() append at `offset`: for bytes that other processes wrote
  // into temp_path() meanwhile (a distributed convert, convert_to_store). Direct appends
  // end here: all writes after it go through the page cache.
  void continue_at(uint64_t offset);
  uint64_t size() const { return size_; }  // bytes written so far
  // Flushes, fsyncs (not a transient file) and closes the temporary file: what can fail for lack
  // of disk fails here.
  // Several outputs of one command are all finished before the first is committed, so that a
  // failure leaves every target as it was (as `isotope extract` does with its mesh and report).
  void finish();  // throws IoError; a second call does nothing
  void commit();  // finish() if not yet, then rename; throws IoError
  const std::string& temp_path() const { return temp_path_; }
  const std::string& path() const { return path_; }  // as named

 private:
  void drain_direct();  // what direct appends hold, to the file; then stdio's (throws IoError)
  void check_region(uint64_t offset, size_t bytes) const;                            // throws IoError
  int write_region_buffered(uint64_t offset, const void* data, size_t bytes) const;  // 0 or errno
  // Whether a region's piece goes past the page cache: a writer thread, and enough whole pages.
  bool goes_direct(uint64_t offset, size_t bytes) const;
  // Writes such a piece at P: its whole pages handed to region_writes_ (from IN_BUFFER, one of its
  // buffers holding P, or copied into its buffers), its partial pages through the page cache.
  void write_direct(uint64_t offset, const unsigned char* p, size_t bytes, unsigned char* in_buffer) const;
  void end_direct();  // no more direct appends; nothing written
  static constexpr size_t kBufferBytes = size_t{256} << 10;
  // The whole pages a piece of a region needs to be written direct (fewer go through the page cache).
  static constexpr uint64_t kMinDirectBytes = uint64_t{64} << 10;
  std::unique_ptr<char[]> buffer_;         // stdio's, for file_ (closed before this is freed)
  std::string path_, target_, temp_path_;  // as named; the file replaced (output_target); temporary
  std::FILE* file_ = nullptr;
  std::unique_ptr<DirectAppends> direct_;        // Appends::direct, until continue_at or finish
  int direct_fd_ = -1;                           // the temporary opened with O_DIRECT, or -1
  int region_fd_ = -1;                           // opened with O_DIRECT at the first large region, or -1
  bool region_tried_ = false;                    // region_fd_ opened (or refused) already
  std::unique_ptr<RegionWrites> region_writes_;  // the writer of region_fd_'s direct writes, or null
  bool transient_ = false;                       // Appends::transient
  bool finished_ = false, committed_ = false;
  int registered_ = -1;  // register_temporary's slot
  uint64_t size_ = 0;
};

}  // namespace isotope
