#pragma once
// Private to the io library's sources (needs hdf5.h, which only the io library sees): an owning HDF5 id
// that is closed on every path, the HDF5 error text that goes into IoError messages, the lock
// every HDF5 call holds, and the dataset lookups the HDF5 readers share.
#include <hdf5.h>

#include <array>
#include <cerrno>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <mutex>
#include <string>
#include <utility>

namespace isotope {

class Hdf5Handle {
 public:
  using Closer = herr_t (*)(hid_t);
  Hdf5Handle(hid_t id, Closer closer) : id_(id), closer_(closer) {}
  Hdf5Handle(Hdf5Handle&& other) noexcept : id_(std::exchange(other.id_, H5I_INVALID_HID)), closer_(other.closer_) {}
  Hdf5Handle& operator=(Hdf5Handle&&) = delete;
  Hdf5Handle(const Hdf5Handle&) = delete;
  Hdf5Handle& operator=(const Hdf5Handle&) = delete;
  ~Hdf5Handle() { (void)close(); }

  explicit operator bool() const { return id_ >= 0; }
  hid_t get() const { return id_; }
  // Explicit close for files being written, whose close flushes and can fail.
  bool close() {
    if (id_ < 0) return true;
    const bool ok = closer_(std::exchange(id_, H5I_INVALID_HID)) >= 0;
    return ok;
  }

 private:
  hid_t id_;
  Closer closer_;
};

// Errors are reported through IoError, so HDF5 must not also print its stack to stderr.
inline void silence_hdf5_errors() { H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr); }

// The most specific message on the current HDF5 error stack (the root cause). System errors
// come back as a long "..., errno = 28, ..." record, which is reduced to the errno text.
inline std::string hdf5_error_detail() {
  std::string detail;
  const auto innermost = [](unsigned n, const H5E_error2_t* err, void* out) noexcept -> herr_t {
    try {  // called from C, so nothing may propagate
      if (n == 0 && err->desc != nullptr) *static_cast<std::string*>(out) = err->desc;
    } catch (...) {
      return -1;
    }
    return 0;
  };
  H5Ewalk2(H5E_DEFAULT, H5E_WALK_UPWARD, innermost, &detail);
  if (detail.empty()) return "HDF5 error";
  const size_t at = detail.find("errno = ");
  if (at == std::string::npos) return detail.substr(0, detail.find('\n'));
  const int err = std::atoi(detail.c_str() + at + 8);
  const std::string text = std::strerror(err);
  return err == ENOSPC || err == EDQUOT ? "disk full (" + text + ")" : text;
}

// Debian's libhdf5 is the serial build, which must not be entered from two threads at once:
// every HDF5 call, handle closes included, runs under this one process-wide lock.
inline std::mutex& hdf5_mutex() {
  static std::mutex m;
  return m;
}

// Defined with the HDF5 box reader; the caller holds hdf5_mutex(). Each throws IoError naming the
// file (and dataset) and what is wrong.
Hdf5Handle open_hdf5_file(const std::string& file);  // exists, is HDF5, opens read-only
// Lists the file's 3-D datasets in the message when DATASET is missing.
Hdf5Handle open_hdf5_dataset(hid_t file_id, const std::string& file, const std::string& dataset);
// Numeric and rank 3; returns the dims as (x, y, z). WHERE names the dataset in messages.
std::array<int64_t, 3> hdf5_dataset_dims(hid_t dataset, const std::string& where);
// The "spacing" and "origin" attributes when present; absent ones leave the values untouched.
void read_hdf5_geometry(hid_t dataset, const std::string& where, std::array<double, 3>& spacing,
                        std::array<double, 3>& origin);

}  // namespace isotope
