#include "io/store_format.h"

#include <xxhash.h>
#include <zstd.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <span>
#include <utility>

#include "engine/critical_rule.h"
#include "io/field_codec.h"
#include "io/io_error.h"

namespace isotope {
namespace {

// Little-endian field writer/reader over a byte buffer (the machine is little-endian; memcpy
// keeps it free of alignment and aliasing trouble).
class Writer {
 public:
  explicit Writer(uint8_t* p) : p_(p) {}
  template <class T>
  void put(T v) {
    std::memcpy(p_, &v, sizeof v);
    p_ += sizeof v;
  }
  uint8_t* pos() const { return p_; }

 private:
  uint8_t* p_;
};

class Reader {
 public:
  explicit Reader(const uint8_t* p) : p_(p) {}
  template <class T>
  T get() {
    T v;
    std::memcpy(&v, p_, sizeof v);
    p_ += sizeof v;
    return v;
  }

 private:
  const uint8_t* p_;
};

constexpr size_t kTypeChars = 16;
constexpr size_t kHeaderChecksumAt = kHeaderBytes - 8;

void put_summary(Writer& w, const BrickSummary& s) {
  for (float f : {s.lo, s.hi, s.max_error_bound, s.max_error_surplus, s.exact_lo, s.exact_hi, s.paper_lo,
                  s.paper_hi, s.max_weight[0], s.max_weight[1], s.max_weight[2]})
    w.put(f);
  w.put(uint32_t{0});
}

BrickSummary get_summary(Reader& r) {
  BrickSummary s;
  for (float* f : {&s.lo, &s.hi, &s.max_error_bound, &s.max_error_surplus, &s.exact_lo, &s.exact_hi, &s.paper_lo,
                   &s.paper_hi, &s.max_weight[0], &s.max_weight[1], &s.max_weight[2]})
    *f = r.get<float>();
  (void)r.get<uint32_t>();
  return s;
}

// The eleven record fields, in their order in a brick.
constexpr int kRecordFields = kBrickFields - 1;
const float& record_field(const Record& r, int f) {
  switch (f) {
    case 0: return r.bounds.lo;
    case 1: return r.bounds.hi;
    case 2: return r.bounds.error_bound;
    case 3: return r.bounds.error_surplus;
    case 4: return r.topology.exact_lo;
    case 5: return r.topology.exact_hi;
    case 6: return r.topology.paper_lo;
    case 7: return r.topology.paper_hi;
    case 8: return r.topology.weight[0];
    case 9: return r.topology.weight[1];
    default: return r.topology.weight[2];
  }
}
float& record_field(Record& r, int f) { return const_cast<float&>(record_field(std::as_const(r), f)); }

}  // namespace

BrickSummary summarize_brick(const BrickContents& b) {
  BrickSummary s;
  float lo = std::numeric_limits<float>::infinity(), hi = -lo;
  for (const Record& r : b.records) {
    if (r.bounds.lo > r.bounds.hi) continue;
    lo = std::min(lo, r.bounds.lo);
    hi = std::max(hi, r.bounds.hi);
    s.max_error_bound = std::max(s.max_error_bound, r.bounds.error_bound);
    s.max_error_surplus = std::max(s.max_error_surplus, r.bounds.error_surplus);
    IsoInterval e{s.exact_lo, s.exact_hi}, p{s.paper_lo, s.paper_hi};
    e.hull({r.topology.exact_lo, r.topology.exact_hi});
    p.hull({r.topology.paper_lo, r.topology.paper_hi});
    s.exact_lo = e.lo, s.exact_hi = e.hi, s.paper_lo = p.lo, s.paper_hi = p.hi;
    for (size_t w = 0; w < s.max_weight.size(); ++w) s.max_weight[w] = std::max(s.max_weight[w], r.topology.weight[w]);
  }
  for (float v : b.values) lo = std::min(lo, v), hi = std::max(hi, v);
  s.lo = lo, s.hi = hi;
  return s;
}

uint64_t store_checksum(const void* data, size_t bytes) { return XXH64(data, bytes, 0); }

std::array<uint8_t, kHeaderBytes> encode_header(const StoreHeader& h) {
  std::array<uint8_t, kHeaderBytes> bytes{};
  Writer w(bytes.data());
  for (char c : kStoreMagic) w.put(c);
  w.put(kStoreVersion);
  w.put(static_cast<uint32_t>(kHeaderBytes));
  for (int64_t d : h.dims) w.put(d);
  for (double d : h.spacing) w.put(d);
  for (double d : h.origin) w.put(d);
  w.put(static_cast<uint8_t>(h.brick_bits));
  w.put(static_cast<uint8_t>(h.lattice_k));
  w.put(static_cast<uint8_t>(h.zstd_level));
  w.put(static_cast<uint8_t>(h.quantize_bits));
  char type[kTypeChars] = {};
  std::memcpy(type, h.source_type.data(), std::min(h.source_type.size(), kTypeChars - 1));
  for (char c : type) w.put(c);
  w.put(h.value_min);
  w.put(h.value_max);
  w.put(h.brick_count);
  w.put(h.directory_offset);
  w.put(h.directory_bytes);
  w.put(h.directory_checksum);
  for (int64_t c : h.critical_paper) w.put(c);
  for (int64_t c : h.critical_exact) w.put(c);
  w.put(h.input_bytes);
  w.put(h.value_offset);
  w.put(h.value_scale);
  const uint64_t sum = store_checksum(bytes.data(), kHeaderChecksumAt);
  std::memcpy(bytes.data() + kHeaderChecksumAt, &sum, sizeof sum);
  return bytes;
}

StoreHeader decode_header(const uint8_t* bytes, size_t size, const std::string& file) {
  if (size < kHeaderBytes)
    throw IoError(file + ": not an isotope store (" + std::to_string(size) + " bytes, shorter than the header)");
  if (std::memcmp(bytes, kStoreMagic.data(), kStoreMagic.size()) != 0)
    throw IoError(file + ": not an isotope store (wrong magic number)");
  Reader r(bytes + kStoreMagic.size());
  const auto version = r.get<uint32_t>();
  if (version != kStoreVersion)
    throw IoError(file + ": store format version " + std::to_string(version) + " is not supported (this isotope reads version " +
                  std::to_string(kStoreVersion) + (version < kStoreVersion ? "; convert the volume again" : "") + ")");
  uint64_t sum;
  std::memcpy(&sum, bytes + kHeaderChecksumAt, sizeof sum);
  if (sum != store_checksum(bytes, kHeaderChecksumAt)) throw IoError(file + ": header checksum mismatch (corrupt header)");
  if (r.get<uint32_t>() != kHeaderBytes) throw IoError(file + ": header size field is wrong");
  StoreHeader h;
  for (int64_t& d : h.dims) d = r.get<int64_t>();
  for (double& d : h.spacing) d = r.get<double>();
  for (double& d : h.origin) d = r.get<double>();
  h.brick_bits = r.get<uint8_t>();
  h.lattice_k = r.get<uint8_t>();
  h.zstd_level = r.get<uint8_t>();
  h.quantize_bits = r.get<uint8_t>();
  char type[kTypeChars];
  for (char& c : type) c = r.get<char>();
  type[kTypeChars - 1] = 0;
  h.source_type = type;
  h.value_min = r.get<double>();
  h.value_max = r.get<double>();
  h.brick_count = r.get<int64_t>();
  h.directory_offset = r.get<uint64_t>();
  h.directory_bytes = r.get<uint64_t>();
  h.directory_checksum = r.get<uint64_t>();
  for (int64_t& c : h.critical_paper) c = r.get<int64_t>();
  for (int64_t& c : h.critical_exact) c = r.get<int64_t>();
  h.input_bytes = r.get<uint64_t>();
  h.value_offset = r.get<double>();
  h.value_scale = r.get<double>();
  if (h.quantize_bits != 0 && h.quantize_bits != 8 && h.quantize_bits != 16)
    throw IoError(file + ": header holds an impossible quantization");
  if (!std::isfinite(h.value_offset) || !(h.value_scale > 0) || !std::isfinite(h.value_scale))
    throw IoError(file + ": header holds an impossible value mapping");

  for (int64_t d : h.dims)
    if (d < 2 || d > (int64_t{1} << 19) + 1) throw IoError(file + ": header holds impossible dimensions");
  if (h.brick_bits < 1 || h.brick_bits > 8) throw IoError(file + ": header holds an impossible brick size");
  const StoreLayout layout(h.dims, h.brick_bits);
  if (layout.lattice().k != h.lattice_k || layout.brick_count() != h.brick_count)
    throw IoError(file + ": header contradicts itself (levels or brick count do not match the dimensions)");
  if (h.directory_bytes != static_cast<uint64_t>(h.brick_count) * kEntryBytes)
    throw IoError(file + ": header gives a directory size that does not match the brick count");
  return h;
}

std::vector<uint8_t> encode_directory(const std::vector<BrickEntry>& entries) {
  std::vector<uint8_t> bytes(entries.size() * kEntryBytes);
  Writer w(bytes.data());
  for (const BrickEntry& e : entries) {
    w.put(e.offset);
    w.put(e.compressed_bytes);
    w.put(e.raw_bytes);
    w.put(e.checksum);
    put_summary(w, e.summary);
  }
  return bytes;
}

std::vector<BrickEntry> decode_directory(const uint8_t* bytes, size_t size, const StoreHeader& h,
                                         const std::string& file) {
  if (size != h.directory_bytes) throw IoError(file + ": directory is truncated");
  if (store_checksum(bytes, size) != h.directory_checksum) throw IoError(file + ": directory checksum mismatch (corrupt directory)");
  std::vector<BrickEntry> entries(static_cast<size_t>(h.brick_count));
  Reader r(bytes);
  for (BrickEntry& e : entries) {
    e.offset = r.get<uint64_t>();
    e.compressed_bytes = r.get<uint32_t>();
    e.raw_bytes = r.get<uint32_t>();
    e.checksum = r.get<uint64_t>();
    e.summary = get_summary(r);
    if (e.offset < kHeaderBytes || e.offset + e.compressed_bytes > h.directory_offset)
      throw IoError(file + ": directory entry " + std::to_string(&e - entries.data()) + " points outside the brick area");
  }
  return entries;
}

std::vector<uint8_t> encode_brick(const std::vector<float>& values, const std::vector<Record>& records,
                                  int zstd_level, BrickEntry& entry) {
  std::vector<uint8_t> raw;
  raw.reserve(values.size() * 4 + records.size() * sizeof(Record));
  encode_field(values, raw);
  if (!records.empty()) {
    std::vector<float> field(records.size());
    for (int f = 0; f < kRecordFields; ++f) {
      for (size_t i = 0; i < field.size(); ++i) field[i] = record_field(records[i], f);
      encode_field(field, raw);
    }
  }
  std::vector<uint8_t> out(ZSTD_compressBound(raw.size()));
  const size_t n = ZSTD_compress(out.data(), out.size(), raw.data(), raw.size(), zstd_level);
  if (ZSTD_isError(n)) throw IoError(std::string("zstd compression failed: ") + ZSTD_getErrorName(n));
  out.resize(n);
  entry.compressed_bytes = static_cast<uint32_t>(n);
  entry.raw_bytes = static_cast<uint32_t>(raw.size());
  entry.checksum = store_checksum(out.data(), out.size());
  return out;
}

void decode_brick(const uint8_t* compressed, const BrickEntry& entry, std::vector<float>& values,
                  std::vector<Record>& records, const std::string& where) {
  if (store_checksum(compressed, entry.compressed_bytes) != entry.checksum)
    throw IoError(where + ": checksum mismatch (corrupt brick)");
  // Generous: a field never takes more than 4 bytes per value plus its header.
  const size_t limit = (values.size() + records.size() * kRecordFields) * 4 + 64 * kBrickFields;
  if (entry.raw_bytes > limit) throw IoError(where + ": impossible uncompressed size");
  std::vector<uint8_t> raw(entry.raw_bytes);
  const size_t n = ZSTD_decompress(raw.data(), raw.size(), compressed, entry.compressed_bytes);
  if (ZSTD_isError(n)) throw IoError(where + ": cannot decompress (" + ZSTD_getErrorName(n) + ")");
  if (n != raw.size()) throw IoError(where + ": decompressed size differs from the directory");
  try {
    const uint8_t* p = decode_field(raw.data(), raw.data() + raw.size(), values);
    if (!records.empty()) {
      std::vector<float> field(records.size());
      for (int f = 0; f < kRecordFields; ++f) {
        p = decode_field(p, raw.data() + raw.size(), field);
        for (size_t i = 0; i < field.size(); ++i) record_field(records[i], f) = field[i];
      }
    }
    if (p != raw.data() + raw.size()) throw IoError("trailing bytes after the last field");
  } catch (const IoError& e) {
    throw IoError(where + ": " + e.what());
  }
}

}  // namespace isotope
