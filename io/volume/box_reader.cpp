#include "io/volume/box_reader.h"

#include <fcntl.h>
#include <hdf5.h>
#include <unistd.h>

#include <algorithm>
#include <bit>
#include <cerrno>
#include <cmath>
#include <cstddef>
#include <filesystem>
#include <memory>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <system_error>
#include <utility>
#include <vector>

#include "io/file/input_file.h"
#include "io/file/positioned_io.h"
#include "io/volume/hdf5_handle.h"
#include "io/volume/nrrd_reader.h"
#include "io/volume/raw_reader.h"
#include "io/volume/tiff_reader.h"
#include "isotope/error.h"

namespace isotope {
namespace {

namespace fs = std::filesystem;

// Bounds the staging buffer of one read_box call however large the box; a whole number of
// values of every type.
constexpr size_t kStageBytes = size_t{1} << 20;

// strerror may share a static buffer between threads; this does not.
std::string errno_text(int err) { return std::error_code(err, std::generic_category()).message(); }

std::string xyz_text(const std::array<int64_t, 3>& v) {
  return "(" + std::to_string(v[0]) + "," + std::to_string(v[1]) + "," + std::to_string(v[2]) + ")";
}

VolumeInfo info_of(ScalarType type, const std::array<int64_t, 3>& dims, const std::array<double, 3>& spacing,
                   const std::array<double, 3>& origin) {
  VolumeInfo info;
  info.dims = dims;
  info.spacing = spacing;
  info.origin = origin;
  info.type = scalar_type_name(type);
  info.element_bytes = scalar_type_size(type);
  info.is_integer = type != ScalarType::float32 && type != ScalarType::float64;
  return info;
}

// ---------------------------------------------------------------- files

class Fd {
 public:
  explicit Fd(int fd) : fd_(fd) {}
  Fd(Fd&& other) noexcept : fd_(std::exchange(other.fd_, -1)) {}
  Fd& operator=(Fd&&) = delete;
  Fd(const Fd&) = delete;
  Fd& operator=(const Fd&) = delete;
  ~Fd() {
    if (fd_ >= 0) ::close(fd_);
  }
  int get() const { return fd_; }

 private:
  int fd_;
};

Fd open_read_only(const std::string& path, const std::string& where) {
  require_regular_file(path, where, "a volume file");
  Fd fd(::open(path.c_str(), O_RDONLY | O_CLOEXEC));
  if (fd.get() < 0) throw IoError(where + ": cannot open: " + errno_text(errno));
  return fd;
}

// The inflated copy of gzip data: a file created under a unique name in DIR, removed when this
// is destroyed.
class InflatedFile {
 public:
  // An empty DIR is the working directory, as everywhere else a relative path is.
  InflatedFile(const std::string& dir, const std::string& purpose)
      : path_((fs::path(dir) / "isotope-inflated-XXXXXX").string()),
        fd_(::mkostemp(path_.data(), O_CLOEXEC)) {  // fills in the X's
    if (fd_.get() < 0) {
      throw IoError((dir.empty() ? "." : dir) + ": cannot create a scratch file to " + purpose + ": " +
                    errno_text(errno));
    }
  }
  ~InflatedFile() { ::unlink(path_.c_str()); }
  InflatedFile(const InflatedFile&) = delete;
  InflatedFile& operator=(const InflatedFile&) = delete;

  const std::string& path() const { return path_; }
  int fd() const { return fd_.get(); }

 private:
  std::string path_;
  Fd fd_;
};

void write_fully(int fd, const unsigned char* bytes, size_t size, const std::string& where) {
  for (size_t done = 0; done < size;) {
    const ssize_t n = ::write(fd, bytes + done, size - done);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) {
      const int err = errno;
      const std::string text = errno_text(err);
      throw IoError(where + ": write failed: " + (err == ENOSPC || err == EDQUOT ? "disk full (" + text + ")" : text));
    }
    done += static_cast<size_t>(n);
  }
}

// pread may return less than asked; only 0 (end of file) or an error end the loop early.
void pread_fully(int fd, unsigned char* out, size_t size, int64_t offset, const std::string& where) {
  const PreadOutcome r = pread_all(fd, out, size, static_cast<uint64_t>(offset));
  const int64_t at = offset + static_cast<int64_t>(r.bytes);
  if (r.error != 0) throw IoError(where + ": read failed at byte " + std::to_string(at) + ": " + errno_text(r.error));
  if (r.ended_early(size)) {
    throw IoError(where + ": short read: the file ends at byte " + std::to_string(at) + ", before byte " +
                  std::to_string(offset + static_cast<int64_t>(size)) + " (was it truncated after opening?)");
  }
}

// ---------------------------------------------------------------- raw values in a file

struct RawData {
  int64_t offset = 0;  // byte of node (0, 0, 0)
  ScalarType type = ScalarType::uint8;
  bool big_endian = false;
  std::string name;       // how messages name the volume
  std::string read_name;  // how read errors name the file read (an inflated copy differs)
  // Whether values of more than a byte are in the other byte order than this machine's.
  bool swapped() const { return big_endian != (std::endian::native == std::endian::big); }
};

// Raw values at a byte offset of one file: each box is read with pread on a descriptor opened
// once, which needs no lock between threads.
class RawBoxReader final : public BoxReader {
 public:
  RawBoxReader(Fd fd, RawData data, const VolumeInfo& info, std::unique_ptr<InflatedFile> scratch)
      : scratch_(std::move(scratch)), fd_(std::move(fd)), data_(std::move(data)) {
    info_ = info;
  }

  void read_box(const std::array<int64_t, 3>& lo, const std::array<int64_t, 3>& size, float* out) const override {
    read_box_unchecked(lo, size, out);
    if (!info_.is_integer) check_finite(out, lo, size, data_.name);  // an integer is finite as float
  }

  void read_box_unchecked(const std::array<int64_t, 3>& lo, const std::array<int64_t, 3>& size,
                          float* out) const override {
    check_box(lo, size, info_, data_.name);
    const int64_t total = size[0] * size[1] * size[2];
    if (total == 0) return;
    const int64_t run = run_length(size);
    const size_t elem = static_cast<size_t>(info_.element_bytes);
    const auto& d = info_.dims;
    const int64_t rows = rows_a_call(size);
    if (rows > 1) {
      Stage stage(static_cast<size_t>(((rows - 1) * d[0] + size[0])) * elem);
      for (int64_t z = 0; z < size[2]; ++z)
        for (int64_t y = 0; y < size[1]; y += rows) read_rows(lo, size, y, std::min(rows, size[1] - y), z, out, stage);
      return;
    }
    // Floats stored as this machine holds them are read straight into OUT: no stage, no copy.
    Stage stage(stored_as_floats() ? 0 : std::min(static_cast<size_t>(run) * elem, kStageBytes));
    for_each_run(lo, size, run, [&](int64_t done, int64_t node) { read_run(node, run, out + done, stage); });
  }

  bool reads_box_alone() const override { return true; }

  // Integers of one or two bytes, in this machine's byte order: those of the other order are
  // swapped where they are read, as HDF5 and libtiff swap theirs.
  std::optional<ScalarType> stored_type() const override {
    if (!info_.is_integer || info_.element_bytes > 2) return std::nullopt;
    return data_.type;
  }

  void read_box_stored(const std::array<int64_t, 3>& lo, const std::array<int64_t, 3>& size,
                       unsigned char* out) const override {
    if (!stored_type()) throw std::logic_error(data_.name + ": values cannot be read as stored");
    check_box(lo, size, info_, data_.name);
    const int64_t run = run_length(size);
    const int64_t elem = info_.element_bytes;
    const bool swap = elem == 2 && data_.swapped();
    for_each_run(lo, size, run, [&](int64_t done, int64_t node) {
      unsigned char* const at = out + done * elem;
      pread_fully(fd_.get(), at, static_cast<size_t>(run * elem), data_.offset + node * elem, data_.read_name);
      if (swap)
        for (int64_t i = 0; i < run; ++i) std::swap(at[2 * i], at[2 * i + 1]);
    });
  }

 private:
  // Calls f(done, node) for each run of RUN nodes of the box that is contiguous in the file (runs
  // of run_length(size)): DONE, the box's nodes before it; NODE, the file's index of its first.
  template <class F>
  void for_each_run(const std::array<int64_t, 3>& lo, const std::array<int64_t, 3>& size, int64_t run,
                    const F& f) const {
    const auto& d = info_.dims;
    const int64_t total = size[0] * size[1] * size[2];
    for (int64_t done = 0; done < total; done += run) {
      const int64_t y = lo[1] + done / size[0] % size[1];
      const int64_t z = lo[2] + done / (size[0] * size[1]);
      f(done, (z * d[1] + y) * d[0] + lo[0]);
    }
  }

  // Nodes of the box that are contiguous in the file: a row, or whole planes when the box spans
  // whole rows, or the whole box when it also spans whole planes.
  int64_t run_length(const std::array<int64_t, 3>& size) const {
    if (size[0] != info_.dims[0]) return size[0];
    if (size[1] != info_.dims[1]) return size[0] * size[1];
    return size[0] * size[1] * size[2];
  }

  // Rows of a box narrower than the volume read several at a call, the gaps between them with
  // them, when a gap is under a page: the page cache reads those pages from the disk anyway, and
  // copying a few KB costs less than a call (a tile's box in a 2048-wide uint8 volume is one call
  // a plane instead of one a row). 1: a row a call.
  int64_t rows_a_call(const std::array<int64_t, 3>& size) const {
    const int64_t elem = info_.element_bytes;
    if (size[0] == info_.dims[0] || size[1] < 2 || (info_.dims[0] - size[0]) * elem > 4096) return 1;
    const int64_t row = info_.dims[0] * elem;
    return std::min(size[1], (static_cast<int64_t>(kStageBytes) - size[0] * elem) / row + 1);
  }
  // Bytes read before they are decoded: not zero-filled, since each read writes them first.
  struct Stage {
    explicit Stage(size_t bytes) : data(bytes > 0 ? new unsigned char[bytes] : nullptr), size(bytes) {}
    std::unique_ptr<unsigned char[]> data;
    size_t size;
  };

  bool stored_as_floats() const { return data_.type == ScalarType::float32 && !data_.swapped(); }

  // ROWS rows of the box from its row Y of plane Z in one read through STAGE.
  void read_rows(const std::array<int64_t, 3>& lo, const std::array<int64_t, 3>& size, int64_t y, int64_t rows,
                 int64_t z, float* out, const Stage& stage) const {
    const int64_t elem = info_.element_bytes;
    const auto& d = info_.dims;
    const int64_t first = ((lo[2] + z) * d[1] + lo[1] + y) * d[0] + lo[0];
    pread_fully(fd_.get(), stage.data.get(), static_cast<size_t>(((rows - 1) * d[0] + size[0]) * elem),
                data_.offset + first * elem, data_.read_name);
    for (int64_t r = 0; r < rows; ++r)
      decode_scalars(data_.type, data_.big_endian, stage.data.get() + r * d[0] * elem, static_cast<size_t>(size[0]),
                     out + (z * size[1] + y + r) * size[0]);
  }

  // COUNT nodes from node index FIRST, through STAGE in pieces when they do not fit, or straight
  // into OUT without one.
  void read_run(int64_t first, int64_t count, float* out, const Stage& stage) const {
    const int64_t elem = info_.element_bytes;
    if (stage.size == 0) {
      pread_fully(fd_.get(), reinterpret_cast<unsigned char*>(out), static_cast<size_t>(count * elem),
                  data_.offset + first * elem, data_.read_name);
      return;
    }
    const int64_t piece = static_cast<int64_t>(stage.size) / elem;
    for (int64_t i = 0; i < count; i += piece) {
      const int64_t n = std::min(piece, count - i);
      pread_fully(fd_.get(), stage.data.get(), static_cast<size_t>(n * elem), data_.offset + (first + i) * elem,
                  data_.read_name);
      decode_scalars(data_.type, data_.big_endian, stage.data.get(), static_cast<size_t>(n), out + i);
    }
  }

  std::unique_ptr<InflatedFile> scratch_;  // the inflated copy being read, if any
  Fd fd_;
  RawData data_;
};

std::unique_ptr<BoxReader> open_raw(const std::string& path, const RawLayout& layout) {
  check_raw_file(path, layout);
  const VolumeInfo info = info_of(layout.type, layout.dims, {1, 1, 1}, {0, 0, 0});
  return std::make_unique<RawBoxReader>(open_read_only(path, path), RawData{0, layout.type, false, path, path}, info,
                                        nullptr);
}

// Inflated once into SCRATCH_DIR, with bounded memory, then read like raw NRRD data.
std::unique_ptr<BoxReader> open_gzip_nrrd(const NrrdLayout& layout, const VolumeInfo& info,
                                          const std::string& scratch_dir) {
  auto scratch = std::make_unique<InflatedFile>(scratch_dir, "inflate " + layout.where);
  const std::string copy = layout.where + ": inflated copy " + scratch->path();
  stream_nrrd_data(layout,
                   [&](const unsigned char* bytes, size_t size) { write_fully(scratch->fd(), bytes, size, copy); });
  Fd fd = open_read_only(scratch->path(), copy);
  RawData data{0, layout.type, layout.big_endian, layout.where, copy};
  return std::make_unique<RawBoxReader>(std::move(fd), std::move(data), info, std::move(scratch));
}

std::unique_ptr<BoxReader> open_nrrd(const std::string& path, const std::string& scratch_dir) {
  const NrrdLayout layout = read_nrrd_layout(path);  // also checks the file holds the data
  const VolumeInfo info = info_of(layout.type, layout.dims, layout.spacing, layout.origin);
  if (layout.encoding == NrrdEncoding::gzip) return open_gzip_nrrd(layout, info, scratch_dir);
  RawData data{layout.data_offset, layout.type, layout.big_endian, layout.where, layout.where};
  return std::make_unique<RawBoxReader>(open_read_only(layout.data_path, layout.where), std::move(data), info, nullptr);
}

// ---------------------------------------------------------------- HDF5

// A dataset that is not raw data at an offset (contiguous_hdf5_data, below): HDF5 selects the box
// as a hyperslab and converts to float (or reads small integers as they are) itself, undoing
// chunking and filters; every call holds hdf5_mutex(), so concurrent boxes are read one after the
// other.
class Hdf5BoxReader final : public BoxReader {
 public:
  Hdf5BoxReader(Hdf5Handle file, Hdf5Handle dataset, std::string where, const VolumeInfo& info)
      : file_(std::move(file)), dataset_(std::move(dataset)), where_(std::move(where)) {
    info_ = info;
  }
  ~Hdf5BoxReader() override {
    const std::lock_guard lock(hdf5_mutex());
    dataset_.close();
    file_.close();
  }
  Hdf5BoxReader(const Hdf5BoxReader&) = delete;
  Hdf5BoxReader& operator=(const Hdf5BoxReader&) = delete;

  void read_box(const std::array<int64_t, 3>& lo, const std::array<int64_t, 3>& size, float* out) const override {
    read_box_unchecked(lo, size, out);
    if (!info_.is_integer) check_finite(out, lo, size, where_);  // an integer is finite as float
  }

  void read_box_unchecked(const std::array<int64_t, 3>& lo, const std::array<int64_t, 3>& size,
                          float* out) const override {
    check_box(lo, size, info_, where_);
    if (size[0] * size[1] * size[2] == 0) return;
    read_hyperslab(lo, size, std::nullopt, out);
  }

  // Integers of one or two bytes, in this machine's byte order (HDF5 swaps a big-endian file's).
  // Converting them to float is HDF5's slowest path: one value at a time, on one thread, through a
  // buffer of its own, which the one-shot march at eps 0 (the raw file's path) need not take.
  std::optional<ScalarType> stored_type() const override {
    const std::optional<ScalarType> t = parse_scalar_type(info_.type);
    if (t == ScalarType::uint8 || t == ScalarType::uint16 || t == ScalarType::int16) return t;
    return std::nullopt;
  }

  void read_box_stored(const std::array<int64_t, 3>& lo, const std::array<int64_t, 3>& size,
                       unsigned char* out) const override {
    const std::optional<ScalarType> type = stored_type();
    if (!type) throw std::logic_error(where_ + ": values cannot be read as stored");
    check_box(lo, size, info_, where_);
    if (size[0] * size[1] * size[2] == 0) return;
    read_hyperslab(lo, size, type, out);
  }

 private:
  // The box as floats, or as STORED values, into OUT: HDF5 converts from the file's type.
  void read_hyperslab(const std::array<int64_t, 3>& lo, const std::array<int64_t, 3>& size,
                      std::optional<ScalarType> stored, void* out) const {
    const hsize_t start[3] = {static_cast<hsize_t>(lo[2]), static_cast<hsize_t>(lo[1]), static_cast<hsize_t>(lo[0])};
    const hsize_t count[3] = {static_cast<hsize_t>(size[2]), static_cast<hsize_t>(size[1]),
                              static_cast<hsize_t>(size[0])};
    const std::lock_guard lock(hdf5_mutex());  // declared first, so released after the handles close
    const Hdf5Handle file_space(H5Dget_space(dataset_.get()), H5Sclose);
    const Hdf5Handle memory_space(H5Screate_simple(3, count, nullptr), H5Sclose);
    const std::string box = " box of size " + xyz_text(size) + " at (x,y,z) = " + xyz_text(lo);
    if (!file_space || !memory_space ||
        H5Sselect_hyperslab(file_space.get(), H5S_SELECT_SET, start, nullptr, count, nullptr) < 0)
      throw IoError(where_ + ": cannot select the" + box + ": " + hdf5_error_detail());
    // H5T_NATIVE_* call into the library (they open it on first use): under the lock too.
    const hid_t memory_type = !stored                         ? H5T_NATIVE_FLOAT
                              : *stored == ScalarType::uint8  ? H5T_NATIVE_UINT8
                              : *stored == ScalarType::uint16 ? H5T_NATIVE_UINT16
                                                              : H5T_NATIVE_INT16;
    if (H5Dread(dataset_.get(), memory_type, memory_space.get(), file_space.get(), H5P_DEFAULT, out) < 0)
      throw IoError(where_ + ": cannot read the" + box + ": " + hdf5_error_detail());
  }

  Hdf5Handle file_;
  Hdf5Handle dataset_;
  std::string where_;
};

// "uint16", "int32", "float64", ...: the dataset's type as stored. The caller holds hdf5_mutex().
void set_hdf5_type(hid_t dataset, const std::string& where, VolumeInfo& info) {
  const Hdf5Handle type(H5Dget_type(dataset), H5Tclose);
  if (!type) throw IoError(where + ": cannot read the type: " + hdf5_error_detail());
  info.is_integer = H5Tget_class(type.get()) == H5T_INTEGER;
  info.element_bytes = static_cast<int>(H5Tget_size(type.get()));
  const bool is_unsigned = info.is_integer && H5Tget_sign(type.get()) == H5T_SGN_NONE;
  info.type =
      std::string(info.is_integer ? (is_unsigned ? "uint" : "int") : "float") + std::to_string(8 * info.element_bytes);
}

// Boxes cut a chunked dataset's chunks (the one-shot march's windows of z-layers), and HDF5 keeps
// 1 MB of decoded chunks by default: a chunk deeper than a window was read and inflated again for
// every window that cut it (docs/METHOD.md, "eps = 0 from a file"). DS is opened again with a
// cache that holds one layer of chunks across the plane, where that takes more than the default
// and at most CACHE_BYTES; a chunk read wholly goes first (w0 = 1). The caller holds
// hdf5_mutex().
Hdf5Handle with_chunk_cache(hid_t file, const std::string& dataset, const std::string& where, Hdf5Handle ds,
                            const VolumeInfo& info, uint64_t cache_bytes) {
  constexpr double kDefaultBytes = 1 << 20;
  const Hdf5Handle create(H5Dget_create_plist(ds.get()), H5Pclose);
  hsize_t zyx[3] = {0, 0, 0};
  if (!create || H5Pget_layout(create.get()) != H5D_CHUNKED || H5Pget_chunk(create.get(), 3, zyx) != 3 ||
      zyx[0] * zyx[1] * zyx[2] == 0)
    return ds;
  const auto chunks_along = [](int64_t nodes, hsize_t chunk) {
    return std::ceil(static_cast<double>(nodes) / static_cast<double>(chunk));
  };
  const double chunk_bytes =
      static_cast<double>(zyx[0]) * static_cast<double>(zyx[1]) * static_cast<double>(zyx[2]) * info.element_bytes;
  const double chunks = chunks_along(info.dims[1], zyx[1]) * chunks_along(info.dims[0], zyx[2]);
  const double layer = chunk_bytes * chunks;
  if (layer <= kDefaultBytes || layer > static_cast<double>(cache_bytes)) return ds;
  // HDF5's guide: slots a prime number about 100 times the chunks the cache holds; a pointer each,
  // allocated at open, so at most 2^18 of them (a hash table of tiny chunks only collides more).
  auto slots = static_cast<size_t>(std::min(100 * chunks, double{1 << 18})) | 1;
  const auto prime = [](size_t n) {
    for (size_t d = 3; d * d <= n; d += 2)
      if (n % d == 0) return false;
    return true;
  };
  while (!prime(slots)) slots += 2;
  const Hdf5Handle access(H5Pcreate(H5P_DATASET_ACCESS), H5Pclose);
  if (!access || H5Pset_chunk_cache(access.get(), slots, static_cast<size_t>(layer), 1.0) < 0) return ds;
  // The cache is the open dataset's: another handle to it while it is open would share its cache.
  ds.close();
  Hdf5Handle again(H5Dopen2(file, dataset.c_str(), access.get()), H5Dclose);
  if (!again) throw IoError(where + ": cannot open it again with a chunk cache: " + hdf5_error_detail());
  VolumeInfo now;  // the same path may have come to name another dataset since
  now.dims = hdf5_dataset_dims(again.get(), where);
  set_hdf5_type(again.get(), where, now);
  if (now.dims != info.dims || now.type != info.type)
    throw IoError(where + ": the dataset changed while it was opened");
  return again;
}

// The values of a dataset stored contiguously, unfiltered and whole in the file HDF5 opened, in a
// type raw data has: where they start, their type and byte order. Such a dataset is raw data at an
// offset, read without the library, its lock or a stage, on every thread at once (docs/METHOD.md,
// "HDF5 datasets"). Anything else (chunks, a compact dataset, external files, space never written,
// other types, another file driver) is left to HDF5, and its messages. The end of file it checks
// against is the one HDF5 knows (which H5Fopen has held the file to). The caller holds
// hdf5_mutex().
std::optional<RawData> contiguous_hdf5_data(hid_t file, hid_t dataset, const VolumeInfo& info) {
  const Hdf5Handle create(H5Dget_create_plist(dataset), H5Pclose);
  if (!create || H5Pget_layout(create.get()) != H5D_CONTIGUOUS || H5Pget_external_count(create.get()) != 0)
    return std::nullopt;
  H5D_space_status_t status{};
  if (H5Dget_space_status(dataset, &status) < 0 || status != H5D_SPACE_STATUS_ALLOCATED) return std::nullopt;
  const uint64_t bytes =
      static_cast<uint64_t>(info.dims[0] * info.dims[1] * info.dims[2]) * static_cast<uint64_t>(info.element_bytes);
  const haddr_t offset = H5Dget_offset(dataset);
  hsize_t file_bytes = 0;
  if (offset == HADDR_UNDEF || H5Dget_storage_size(dataset) != bytes || H5Fget_filesize(file, &file_bytes) < 0 ||
      offset > file_bytes || file_bytes - offset < bytes)
    return std::nullopt;
  const Hdf5Handle type(H5Dget_type(dataset), H5Tclose);
  if (!type) return std::nullopt;
  struct Known {
    hid_t little, big;
    ScalarType as;
  };
  const Known known[] = {{H5T_STD_U8LE, H5T_STD_U8BE, ScalarType::uint8},
                         {H5T_STD_U16LE, H5T_STD_U16BE, ScalarType::uint16},
                         {H5T_STD_I16LE, H5T_STD_I16BE, ScalarType::int16},
                         {H5T_IEEE_F32LE, H5T_IEEE_F32BE, ScalarType::float32},
                         {H5T_IEEE_F64LE, H5T_IEEE_F64BE, ScalarType::float64}};
  for (const Known& k : known) {
    for (const bool big : {false, true})
      if (H5Tequal(type.get(), big ? k.big : k.little) > 0)
        return RawData{static_cast<int64_t>(offset), k.as, big, {}, {}};
  }
  return std::nullopt;
}

// The descriptor HDF5 read FILE through, duplicated: the file whose layout it read, whatever its
// path names now. -1 where the driver holds none. The caller holds hdf5_mutex().
int duplicate_hdf5_descriptor(hid_t file) {
  const Hdf5Handle access(H5Fget_access_plist(file), H5Pclose);
  if (!access || H5Pget_driver(access.get()) != H5FD_SEC2) return -1;  // whose handle is a descriptor
  void* handle = nullptr;
  if (H5Fget_vfd_handle(file, H5P_DEFAULT, &handle) < 0 || handle == nullptr) return -1;
  return ::fcntl(*static_cast<int*>(handle), F_DUPFD_CLOEXEC, 0);
}

std::unique_ptr<BoxReader> open_hdf5(const std::string& file, const std::string& dataset, uint64_t chunk_cache_bytes) {
  const std::lock_guard lock(hdf5_mutex());  // declared first, so released after the handles close
  Hdf5Handle f = open_hdf5_file(file);
  Hdf5Handle ds = open_hdf5_dataset(f.get(), file, dataset);
  const std::string where = file + ":" + dataset;
  VolumeInfo info;
  info.dims = hdf5_dataset_dims(ds.get(), where);  // also checks the type is numeric
  checked_node_count(info.dims, static_cast<int>(sizeof(float)), where);
  read_hdf5_geometry(ds.get(), where, info.spacing, info.origin);
  set_hdf5_type(ds.get(), where, info);
  if (std::optional<RawData> raw = contiguous_hdf5_data(f.get(), ds.get(), info)) {
    Fd fd(duplicate_hdf5_descriptor(f.get()));
    if (fd.get() >= 0) {
      raw->name = where;
      raw->read_name = file;
      return std::make_unique<RawBoxReader>(std::move(fd), std::move(*raw), info, nullptr);
    }
  }
  Hdf5Handle cached = with_chunk_cache(f.get(), dataset, where, std::move(ds), info, chunk_cache_bytes);
  return std::make_unique<Hdf5BoxReader>(std::move(f), std::move(cached), where, info);
}

}  // namespace

// A size of 0 is inside (it reads nothing). lo + size is never formed, so it cannot overflow.
void check_box(const std::array<int64_t, 3>& lo, const std::array<int64_t, 3>& size, const VolumeInfo& info,
               const std::string& where) {
  for (int axis = 0; axis < 3; ++axis) {
    if (lo[axis] < 0 || size[axis] < 0 || size[axis] > info.dims[axis] - lo[axis]) {
      throw std::invalid_argument(where + ": box of size " + xyz_text(size) + " at (x,y,z) = " + xyz_text(lo) +
                                  " is not inside the volume of size " + xyz_text(info.dims));
    }
  }
}

std::unique_ptr<BoxReader> open_box_reader(const VolumeSpec& source, const std::string& scratch_dir,
                                           uint64_t hdf5_chunk_cache_bytes) {
  const VolumeLocation at = locate_volume(source);
  std::unique_ptr<BoxReader> reader;
  switch (at.format) {
    case VolumeLocation::Format::hdf5: reader = open_hdf5(at.file, at.dataset, hdf5_chunk_cache_bytes); break;
    case VolumeLocation::Format::nrrd: reader = open_nrrd(at.file, scratch_dir); break;
    case VolumeLocation::Format::tiff: reader = open_tiff_stack(at.file); break;
    case VolumeLocation::Format::raw: reader = open_raw(at.file, at.layout); break;
  }
  const VolumeInfo& info = reader->info();
  check_volume_layout(info.dims, info.spacing, info.origin, at.file);
  return reader;
}

}  // namespace isotope
