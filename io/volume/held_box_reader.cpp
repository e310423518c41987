#include "io/volume/held_box_reader.h"

#include <algorithm>
#include <bit>
#include <cstring>
#include <string>

#include "io/volume/raw_reader.h"

namespace isotope {

int64_t HeldBoxReader::value_bytes_of(const BoxReader& input) {
  return input.stored_type() ? input.info().element_bytes : static_cast<int64_t>(sizeof(float));
}

uint64_t HeldBoxReader::held_bytes(const BoxReader& input) {
  const VolumeInfo& i = input.info();
  const auto nodes =
      static_cast<uint64_t>(i.dims[0]) * static_cast<uint64_t>(i.dims[1]) * static_cast<uint64_t>(i.dims[2]);
  return nodes * static_cast<uint64_t>(value_bytes_of(input));
}

// About kReadBytes a call by default: enough that a call's cost is nothing beside its copy, few
// enough planes that the first box waits for little more than its own.
HeldBoxReader::HeldBoxReader(const BoxReader& input, int64_t read_bytes) : input_(input) {
  info_ = input.info();
  stored_ = input.stored_type().has_value();
  value_bytes_ = value_bytes_of(input);
  plane_nodes_ = info_.dims[0] * info_.dims[1];
  read_planes_ = std::clamp<int64_t>(read_bytes / std::max<int64_t>(1, plane_nodes_ * value_bytes_), 1, info_.dims[2]);
  // Not zero-filled: each plane is written by its read before any box reads it. In huge pages,
  // few faults, where the volume is large enough that zeroing a huge page at its first touch
  // costs no more than what it holds (a 66^3 volume of bytes would pay for 2 MB to hold 0.3).
  const auto bytes = static_cast<size_t>(held_bytes(input));
  if (bytes >= 4 * detail::kHugePage)
    held_ = (huge_ = detail::make_huge_array<unsigned char>(bytes)).get();
  else
    held_ = (small_ = std::make_unique_for_overwrite<unsigned char[]>(bytes)).get();
}

HeldBoxReader::~HeldBoxReader() = default;

void HeldBoxReader::read_planes_to(int64_t end) const {
  if (held_planes_.load(std::memory_order_acquire) >= end) return;
  const std::lock_guard<std::mutex> lock(read_mutex_);
  if (failed_) std::rethrow_exception(failed_);
  for (int64_t z = held_planes_.load(std::memory_order_relaxed); z < end;) {
    const int64_t n = std::min(read_planes_, info_.dims[2] - z);
    unsigned char* at = held_ + z * plane_nodes_ * value_bytes_;
    try {
      if (stored_)
        input_.read_box_stored({0, 0, z}, {info_.dims[0], info_.dims[1], n}, at);
      else
        input_.read_box({0, 0, z}, {info_.dims[0], info_.dims[1], n}, reinterpret_cast<float*>(at));
    } catch (...) {
      failed_ = std::current_exception();
      throw;
    }
    z += n;
    held_planes_.store(z, std::memory_order_release);
  }
}

void HeldBoxReader::read_box(const std::array<int64_t, 3>& lo, const std::array<int64_t, 3>& size, float* out) const {
  check_box(lo, size, info_, "the input");
  if (size[0] * size[1] * size[2] == 0) return;
  read_planes_to(lo[2] + size[2]);
  const auto& d = info_.dims;
  const ScalarType type = stored_ ? *input_.stored_type() : ScalarType::float32;
  for (int64_t z = 0; z < size[2]; ++z)
    for (int64_t y = 0; y < size[1]; ++y) {
      const unsigned char* row = held_ + (((lo[2] + z) * d[1] + lo[1] + y) * d[0] + lo[0]) * value_bytes_;
      float* to = out + (z * size[1] + y) * size[0];
      if (stored_)  // held in this machine's byte order (read_box_stored)
        decode_scalars(type, std::endian::native == std::endian::big, row, static_cast<size_t>(size[0]), to);
      else
        std::memcpy(to, row, static_cast<size_t>(size[0]) * sizeof(float));
    }
}

}  // namespace isotope
