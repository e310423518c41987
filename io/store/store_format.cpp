#include "io/store/store_format.h"

#include <xxhash.h>
// For ZSTD_c_literalCompressionMode, a parameter of zstd's experimental API (encode_brick).
#define ZSTD_STATIC_LINKING_ONLY
#include <zstd.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstddef>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <memory>
#include <new>
#include <span>
#include <stdexcept>
#include <type_traits>
#include <utility>

#include "engine/core/huge_blocks.h"
#include "engine/core/volume_check.h"
#include "io/file/checked_size.h"
#include "io/store/field_codec.h"
#include "io/store/held_words.h"
#include "isotope/error.h"

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

// The fields of each section, in order; a bfloat16 field holds floats whose low 16 bits are zero.
enum class Field { values, lo, hi, bound, exact_lo, exact_hi, w0, w1, w2, paper_lo, paper_hi, surplus };
std::span<const Field> fields_of(Section s, bool records) {
  static constexpr Field kCore[] = {Field::values, Field::lo, Field::hi, Field::bound};
  static constexpr Field kExact[] = {Field::exact_lo, Field::exact_hi};
  static constexpr Field kWeights[] = {Field::w0, Field::w1, Field::w2};
  static constexpr Field kExtra[] = {Field::paper_lo, Field::paper_hi, Field::surplus};
  switch (s) {
    case Section::core: return records ? std::span<const Field>(kCore) : std::span<const Field>(kCore, 1);
    case Section::exact: return records ? kExact : std::span<const Field>{};
    case Section::weights: return records ? kWeights : std::span<const Field>{};
    case Section::extra: return records ? kExtra : std::span<const Field>{};
  }
  return {};
}

// A record field of Morton code m as a float, and back (the bfloat16 ones from their bits).
float get_field(const BrickView& b, Field f, uint32_t m) {
  const PackedBounds p = bounds_of(b.bounds[m]);
  switch (f) {
    case Field::values: return b.values[m];
    case Field::lo: return bf16_to_float(p.lo);
    case Field::hi: return bf16_to_float(p.hi);
    case Field::bound: return p.bound;
    case Field::exact_lo: return bf16_to_float(static_cast<Bf16>(b.exact[m]));
    case Field::exact_hi: return bf16_to_float(static_cast<Bf16>(b.exact[m] >> 16));
    case Field::w0: return bf16_to_float(static_cast<Bf16>(b.weights[m]));
    case Field::w1: return bf16_to_float(static_cast<Bf16>(b.weights[m] >> 16));
    case Field::w2: return bf16_to_float(static_cast<Bf16>(b.weights[m] >> 32));
    case Field::paper_lo: return bf16_to_float(static_cast<Bf16>(b.paper[m]));
    case Field::paper_hi: return bf16_to_float(static_cast<Bf16>(b.paper[m] >> 16));
    case Field::surplus: return bf16_to_float(b.surplus[m]);
  }
  return 0;
}

// The zstd contexts' workspaces (hundreds of KB, once a thread) faulted in by one call when zstd
// allocates them, before its first reset writes them a page at a time (docs/METHOD.md, "Fresh
// memory"): a small volume's convert took a tenth of its page faults there.
void* allocate_prefaulted(void*, size_t bytes) {
  void* p = std::malloc(bytes);
  if (p) detail::prefault(p, bytes);
  return p;
}
void free_prefaulted(void*, void* p) { std::free(p); }
constexpr ZSTD_customMem kPrefaultedMemory{allocate_prefaulted, free_prefaulted, nullptr};

// zstd contexts kept per thread: ZSTD_compress and ZSTD_decompress make and initialize a context
// per call, which for small bricks cost more than the (de)compression itself (at level 3, hundreds
// of KB of tables cleared per brick).
ZSTD_CCtx* compression_context() {
  thread_local const std::unique_ptr<ZSTD_CCtx, size_t (*)(ZSTD_CCtx*)> context(
      ZSTD_createCCtx_advanced(kPrefaultedMemory), ZSTD_freeCCtx);
  if (!context) throw std::bad_alloc();
  return context.get();
}
ZSTD_DCtx* decompression_context() {
  thread_local const std::unique_ptr<ZSTD_DCtx, size_t (*)(ZSTD_DCtx*)> context(
      ZSTD_createDCtx_advanced(kPrefaultedMemory), ZSTD_freeDCtx);
  if (!context) throw std::bad_alloc();
  return context.get();
}

}  // namespace

StoreSections sections_for(const RecordFields& f) { return {true, f.exact, f.weights, f.paper || f.surplus}; }

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
  for (int64_t c : h.critical_paper) w.put(c);
  for (int64_t c : h.critical_exact) w.put(c);
  w.put(h.input_bytes);
  w.put(h.value_offset);
  w.put(h.value_scale);
  Writer table(bytes.data() + kBandTableAt);
  for (const BandDirectory& d : h.bands) {
    table.put(d.offset);
    table.put(d.bytes);
    table.put(d.checksum);
  }
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
    throw IoError(file + ": store format version " + std::to_string(version) +
                  " is not supported (this isotope reads version " + std::to_string(kStoreVersion) +
                  (version < kStoreVersion ? "; convert the volume again" : "") + ")");
  uint64_t sum;
  std::memcpy(&sum, bytes + kHeaderChecksumAt, sizeof sum);
  if (sum != store_checksum(bytes, kHeaderChecksumAt))
    throw IoError(file + ": header checksum mismatch (corrupt header)");
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
  if (type[kTypeChars - 1] != 0) throw IoError(file + ": header holds an unterminated element type");
  h.source_type = type;
  h.value_min = r.get<double>();
  h.value_max = r.get<double>();
  h.brick_count = r.get<int64_t>();
  for (int64_t& c : h.critical_paper) c = r.get<int64_t>();
  for (int64_t& c : h.critical_exact) c = r.get<int64_t>();
  h.input_bytes = r.get<uint64_t>();
  h.value_offset = r.get<double>();
  h.value_scale = r.get<double>();
  Reader table(bytes + kBandTableAt);
  for (BandDirectory& d : h.bands) {
    d.offset = table.get<uint64_t>();
    d.bytes = table.get<uint64_t>();
    d.checksum = table.get<uint64_t>();
  }
  // Every field within the range the format allows (docs/FORMAT.md, "Header").
  for (size_t at = 204; at < kBandTableAt; ++at)
    if (bytes[at] != 0) throw IoError(file + ": header's reserved bytes are not zero");
  for (size_t at = kBandTableAt + kMaxBands * 24; at < kHeaderChecksumAt; ++at)
    if (bytes[at] != 0) throw IoError(file + ": header's reserved bytes are not zero");
  for (int64_t d : h.dims)
    if (d < 2 || d > (int64_t{1} << 19) + 1) throw IoError(file + ": header holds impossible dimensions");
  for (int a = 0; a < 3; ++a) {
    if (!std::isfinite(h.spacing[a]) || !(h.spacing[a] > 0))
      throw IoError(file + ": header holds a spacing that is not a positive number");
    if (!std::isfinite(h.origin[a])) throw IoError(file + ": header holds an origin that is not finite");
  }
  if (h.brick_bits < kMinBrickBits || h.brick_bits > kMaxBrickBits)
    throw IoError(file + ": header holds an impossible brick size");
  if (h.zstd_level < 1 || h.zstd_level > 19) throw IoError(file + ": header holds an impossible zstd level");
  if (h.quantize_bits != 0 && h.quantize_bits != 8 && h.quantize_bits != 16)
    throw IoError(file + ": header holds an impossible quantization");
  if (!std::isfinite(h.value_offset) || !(h.value_scale > 0) || !std::isfinite(h.value_scale) ||
      (h.quantize_bits == 0 && (h.value_offset != 0 || h.value_scale != 1)))
    throw IoError(file + ": header holds an impossible value mapping");
  // The values are floats however they are stored, so their range is within float's: beyond it no finite
  // isovalue could be asked of the store.
  if (!within_float_range(h.value_min) || !within_float_range(h.value_max) || !(h.value_min <= h.value_max))
    throw IoError(file + ": header holds an impossible value range");
  const StoreLayout layout(h.dims, h.brick_bits);
  if (layout.lattice().k != h.lattice_k || layout.brick_count() != h.brick_count)
    throw IoError(file + ": header contradicts itself (levels or brick count do not match the dimensions)");
  for (int j = 0; j < kMaxBands; ++j) {
    const BandDirectory& d = h.bands[static_cast<size_t>(j)];
    const uint64_t expected = j <= h.lattice_k ? static_cast<uint64_t>(layout.band(j).brick_count()) * kEntryBytes : 0;
    if (d.bytes != expected || (j > h.lattice_k && (d.offset != 0 || d.checksum != 0)))
      throw IoError(file + ": header gives band " + std::to_string(j) + " a directory that does not match its bricks");
  }
  return h;
}

std::vector<uint8_t> encode_directory(const std::vector<BrickEntry>& entries) {
  std::vector<uint8_t> bytes(entries.size() * kEntryBytes);
  Writer w(bytes.data());
  for (const BrickEntry& e : entries) {
    w.put(e.offset);
    for (uint32_t b : e.bytes) w.put(b);
  }
  return bytes;
}

static_assert(sizeof(BrickEntry) == kEntryBytes && std::is_trivially_copyable_v<BrickEntry> &&
              offsetof(BrickEntry, bytes) == sizeof(uint64_t) && std::endian::native == std::endian::little);

namespace {

// Whether the entries that take room, taken in the Morton order of their bricks (the file order,
// docs/FORMAT.md), each start where the one before ends: the writer's own order, walked without a
// sort or any memory beyond a short stack. Depth first over the power-of-two cube around `grid`,
// children in Morton order (x, then y, then z), cells outside the grid left out.
bool tiles_in_file_order(std::span<const BrickEntry> entries, const Box3& grid) {
  int64_t side = 1;
  while (side < std::max({grid[0], grid[1], grid[2]})) side *= 2;
  struct Cell {
    int64_t x, y, z, size;
  };
  std::vector<Cell> stack{{0, 0, 0, side}};
  uint64_t end = 0;
  bool first = true;
  auto next = [&](int64_t x, int64_t y, int64_t z) {
    if (x >= grid[0] || y >= grid[1] || z >= grid[2]) return true;
    const BrickEntry& e = entries[static_cast<size_t>((z * grid[1] + y) * grid[0] + x)];
    if (e.total() == 0) return true;
    if (!first && e.offset != end) return false;
    first = false;
    end = e.offset + e.total();
    return true;
  };
  while (!stack.empty()) {
    const Cell c = stack.back();
    stack.pop_back();
    if (c.x >= grid[0] || c.y >= grid[1] || c.z >= grid[2]) continue;
    if (c.size == 1) {
      if (!next(c.x, c.y, c.z)) return false;
      continue;
    }
    if (c.size == 2) {  // the eight bricks at once, sparing the stack seven eighths of its pushes
      for (int i = 0; i < 8; ++i)
        if (!next(c.x + (i & 1), c.y + (i >> 1 & 1), c.z + (i >> 2 & 1))) return false;
      continue;
    }
    const int64_t h = c.size / 2;
    for (int i = 7; i >= 0; --i)
      stack.push_back({c.x + (i & 1) * h, c.y + (i >> 1 & 1) * h, c.z + (i >> 2 & 1) * h, h});
  }
  return true;
}

}  // namespace

void check_directory(std::span<const BrickEntry> entries, const Box3& grid, const BandDirectory& d, uint64_t area_end,
                     const std::string& file) {
  if (static_cast<int64_t>(entries.size()) != grid[0] * grid[1] * grid[2])
    throw std::logic_error("check_directory: the entries are not the grid's bricks");
  if (store_checksum(entries.data(), entries.size_bytes()) != d.checksum)
    throw IoError(file + ": directory checksum mismatch (corrupt directory)");
  for (const BrickEntry& e : entries) {
    if (e.offset < kHeaderBytes || !range_within(e.offset, e.total(), area_end))
      throw IoError(file + ": directory entry " + std::to_string(&e - entries.data()) +
                    " points outside the brick area");
    for (uint32_t b : e.bytes)
      if (b != 0 && b <= kChecksumBytes)
        throw IoError(file + ": directory entry " + std::to_string(&e - entries.data()) + " gives a section no room");
  }
  // The band's bricks tile one run of the file (the writer puts them one after the other): no two
  // share bytes, since an entry that points into another brick (a copy of one passes every
  // checksum) would give a silently wrong brick, and none leaves a gap. verify checks that the
  // bands tile the whole brick area; a band read alone checks its own, in the order of offsets.
  // The writer's Morton order is that order (docs/FORMAT.md, "File order"), so it is walked first:
  // at 2048^3 band 0's 2 M entries take a few milliseconds where the sort took a tenth of a second.
  // Any other order, and every fault, goes to the sort, which names the first fault.
  if (tiles_in_file_order(entries, grid)) return;
  // That order comes from a bucket sort: the run's bytes cut into as many equal spans as there are
  // entries, each entry in the span of its offset, a span's few entries sorted among themselves:
  // linear, and the order a sort of (offset, entry) pairs gives, so the same first fault is named.
  uint64_t first = std::numeric_limits<uint64_t>::max(), last = 0;
  size_t with_bytes = 0;  // an entry of no bytes takes no room: left out
  for (const BrickEntry& e : entries)
    if (e.total() != 0) {
      ++with_bytes;
      first = std::min(first, e.offset);
      last = std::max(last, e.offset + e.total());  // no wrap: checked above
    }
  if (with_bytes < 2) return;
  const double per_span = static_cast<double>(last - first) / static_cast<double>(with_bytes);
  auto span_of = [&](uint64_t offset) {
    return std::min(with_bytes - 1, static_cast<size_t>(static_cast<double>(offset - first) / per_span));
  };
  // Counting sort by span, of entry numbers only (4 bytes each, and as many span bounds: half the
  // fresh memory of (offset, entry) pairs), then each span's few entries by offset, ties by number.
  std::vector<uint32_t> ends(with_bytes + 1, 0);  // where each span's entries end in `order`
  for (const BrickEntry& e : entries)
    if (e.total() != 0) ++ends[span_of(e.offset)];
  for (size_t b = 1; b <= with_bytes; ++b) ends[b] += ends[b - 1];
  std::vector<uint32_t> order(with_bytes);
  for (size_t i = entries.size(); i-- > 0;)  // from the back, so that each span's entries fill it from its end
    if (entries[i].total() != 0) order[--ends[span_of(entries[i].offset)]] = static_cast<uint32_t>(i);
  // ends[b] is now where span b begins (ends[with_bytes] stayed the count).
  auto by_offset = [&](uint32_t x, uint32_t y) {
    return entries[x].offset != entries[y].offset ? entries[x].offset < entries[y].offset : x < y;
  };
  for (size_t b = 0; b < with_bytes; ++b)
    if (ends[b + 1] - ends[b] > 1) std::sort(order.begin() + ends[b], order.begin() + ends[b + 1], by_offset);
  for (size_t i = 1; i < order.size(); ++i) {
    const BrickEntry& before = entries[order[i - 1]];
    const uint64_t at = entries[order[i]].offset, end = before.offset + before.total();
    if (at != end)
      throw IoError(file + ": directory entry " + std::to_string(order[i]) +
                    (at < end ? " overlaps entry " : " leaves a gap after entry ") + std::to_string(order[i - 1]) +
                    " (corrupt directory)");
  }
}

BrickFields fields_of(const StoreLayout& layout, int band, const BrickView& brick) {
  const auto nodes = static_cast<uint32_t>(layout.brick_nodes());
  BrickFields out;
  out.values.assign(brick.values, brick.values + nodes);
  if (!stores_records(layout, band)) return out;
  static constexpr Field kOrder[BrickFields::count] = {Field::lo,       Field::hi,       Field::bound,  Field::exact_lo,
                                                       Field::exact_hi, Field::w0,       Field::w1,     Field::w2,
                                                       Field::paper_lo, Field::paper_hi, Field::surplus};
  for (int f = 0; f < BrickFields::count; ++f)
    for (uint32_t m = 0; m < nodes; ++m)
      if ((m & 7) != 0) out.records[static_cast<size_t>(f)].push_back(get_field(brick, kOrder[f], m));
  return out;
}

std::array<std::vector<uint8_t>, kSections> encode_brick(const StoreLayout& layout, int band, const BrickFields& brick,
                                                         int zstd_level, const StoreSections& which) {
  const bool records = stores_records(layout, band);
  auto field_of = [&](Field f) -> const std::vector<float>& {
    switch (f) {
      case Field::values: return brick.values;
      case Field::lo: return brick.records[BrickFields::lo];
      case Field::hi: return brick.records[BrickFields::hi];
      case Field::bound: return brick.records[BrickFields::bound];
      case Field::exact_lo: return brick.records[BrickFields::exact_lo];
      case Field::exact_hi: return brick.records[BrickFields::exact_hi];
      case Field::w0: return brick.records[BrickFields::w0];
      case Field::w1: return brick.records[BrickFields::w1];
      case Field::w2: return brick.records[BrickFields::w2];
      case Field::paper_lo: return brick.records[BrickFields::paper_lo];
      case Field::paper_hi: return brick.records[BrickFields::paper_hi];
      case Field::surplus: return brick.records[BrickFields::surplus];
    }
    return brick.values;
  };
  std::array<std::vector<uint8_t>, kSections> out;
  thread_local std::vector<uint8_t> raw, frame;
  for (int s = 0; s < kSections; ++s) {
    const auto fields = fields_of(static_cast<Section>(s), records);
    if (fields.empty() || !which[static_cast<size_t>(s)]) continue;
    raw.clear();
    size_t bits = 0;  // bytes of float fields (not bfloat16) written as their bit patterns
    for (const Field f : fields) {
      const size_t before = raw.size();
      const FieldCoding coding = encode_field(field_of(f), raw);
      if (coding == FieldCoding::bits && (f == Field::values || f == Field::bound)) bits += raw.size() - before;
    }
    frame.resize(std::max(frame.size(), ZSTD_compressBound(raw.size())));  // grown, never cleared again
    // A section mostly of float bit patterns (float volumes stored losslessly) leaves its
    // literals as they are: what zstd does not match there is the floats' low bytes, about as
    // random as the data's noise, and Huffman-coding them took a third of the compression's time
    // for a few tenths of a percent to a few percent of the store (docs/FORMAT.md, "Sections").
    // The context's parameters are sticky: both set for every section, after a reset of the
    // session (a frame an earlier error left half made would refuse them), so that a section's
    // bytes never depend on what its thread compressed before.
    ZSTD_CCtx* const context = compression_context();
    const auto check = [](size_t code) {
      if (ZSTD_isError(code)) throw IoError(std::string("zstd compression failed: ") + ZSTD_getErrorName(code));
      return code;
    };
    check(ZSTD_CCtx_reset(context, ZSTD_reset_session_only));
    check(ZSTD_CCtx_setParameter(context, ZSTD_c_compressionLevel, zstd_level));
    check(ZSTD_CCtx_setParameter(context, ZSTD_c_literalCompressionMode,
                                 2 * bits >= raw.size() ? ZSTD_ps_disable : ZSTD_ps_auto));
    const size_t n = check(ZSTD_compress2(context, frame.data(), frame.size(), raw.data(), raw.size()));
    std::vector<uint8_t>& bytes = out[static_cast<size_t>(s)];
    bytes.resize(kChecksumBytes + n);
    const uint64_t sum = store_checksum(frame.data(), n);
    std::memcpy(bytes.data(), &sum, sizeof sum);
    std::memcpy(bytes.data() + kChecksumBytes, frame.data(), n);
  }
  return out;
}

namespace {

// One core field of a one-byte store's records (lo, hi or bound: float bits, one per record) into
// the records' narrow words (narrow_word_of), as narrow_bounds() narrows the 64-bit words
// decode_section would otherwise scatter them into: the same words and the same refusals, without
// the wide words in between. Branch-free over the records, so that it vectorizes. Returns nonzero
// where a value has no narrow form (a range that is not an integer of 0..255, a bound not a
// multiple of a half up to 32767 nor +inf); throws IoError where a bfloat16 field holds another
// value, as decode_section's scatter does.
template <Field F>
uint32_t narrow_field(const uint32_t* bits, size_t count, uint32_t* words) {
  uint32_t bad = 0, low = 0;
  for (size_t i = 0; i < count; ++i) {
    const uint32_t b = bits[i];
    if constexpr (F == Field::bound) {
      words[i] |= narrow_bound(b, bad);
    } else {
      words[i] |= narrow_code(b, bad) << (F == Field::hi ? 8 : 0);
      low |= b;
    }
  }
  if ((low & 0xffffu) != 0) throw IoError("a field of bfloat16 codes holds another value");
  return bad;
}

}  // namespace

void decode_section(const StoreLayout& layout, int band, Section s, const uint8_t* bytes, size_t size,
                    const BrickView& out, float* values, const std::string& where, const NarrowBrick* narrow) {
  const bool records = stores_records(layout, band);
  const auto fields = fields_of(s, records);
  if (fields.empty()) {
    if (size != 0) throw IoError(where + ": a section this band does not store is not empty");
    return;
  }
  if (size <= kChecksumBytes) throw IoError(where + ": a section is missing");
  uint64_t sum;
  std::memcpy(&sum, bytes, sizeof sum);
  if (store_checksum(bytes + kChecksumBytes, size - kChecksumBytes) != sum)
    throw IoError(where + ": checksum mismatch (corrupt brick)");
  const auto nodes = static_cast<uint32_t>(layout.brick_nodes());
  const uint32_t record_count = nodes - nodes / 8;
  // Generous: a field never takes more than 4 bytes per value plus a header.
  const uint64_t limit = fields.size() * (uint64_t{nodes} * 4 + 64);
  const unsigned long long declared = ZSTD_getFrameContentSize(bytes + kChecksumBytes, size - kChecksumBytes);
  if (declared == ZSTD_CONTENTSIZE_ERROR || declared == ZSTD_CONTENTSIZE_UNKNOWN || declared > limit)
    throw IoError(where + ": impossible uncompressed size");
  thread_local std::vector<uint8_t> raw;
  raw.resize(declared);
  const size_t n = ZSTD_decompressDCtx(decompression_context(), raw.data(), raw.size(), bytes + kChecksumBytes,
                                       size - kChecksumBytes);
  if (ZSTD_isError(n)) throw IoError(where + ": cannot decompress (" + ZSTD_getErrorName(n) + ")");
  if (n != raw.size()) throw IoError(where + ": decompressed size differs from the frame's");
  // The words the section's fields fill part by part start at zero.
  uint32_t* const narrow_words = narrow && s == Section::core && records ? narrow->words : nullptr;
  thread_local std::vector<uint32_t> records_narrow;  // narrow: the records' words, in record order
  if (narrow_words) records_narrow.assign(record_count, 0);
  switch (s) {
    case Section::core:
      if (records && !narrow_words) std::fill_n(out.bounds, nodes, 0);
      break;
    case Section::exact: std::fill_n(out.exact, nodes, 0); break;
    case Section::weights: std::fill_n(out.weights, nodes, 0); break;
    case Section::extra: std::fill_n(out.paper, nodes, 0), std::fill_n(out.surplus, nodes, 0); break;
  }
  thread_local std::vector<float> field;
  uint32_t not_held = 0;  // narrow: some record has no narrow word
  try {
    const uint8_t* p = raw.data();
    const uint8_t* end = raw.data() + raw.size();
    for (const Field f : fields) {
      if (f == Field::values) {
        if (!narrow) {
          p = decode_field(p, end, std::span<float>(values, nodes));
          continue;
        }
        p = decode_field(p, end, std::span<uint8_t>(narrow->values, nodes));
        if (!p) throw IoError(std::string(narrow->value_not_held) + " (corrupt brick)");
        continue;
      }
      field.resize(record_count);
      p = decode_field(p, end, field);
      const uint32_t* bits = reinterpret_cast<const uint32_t*>(field.data());
      // Scatter over the record slots (Morton codes not multiples of 8) into the field's word.
      auto scatter = [&](auto* words, int shift, bool bf16) {
        using W = std::remove_pointer_t<decltype(words)>;
        uint32_t low = 0;
        size_t i = 0;
        for (uint32_t base = 0; base < nodes; base += 8)
          for (uint32_t k = 1; k < 8; ++k, ++i) {
            low |= bits[i];
            words[base + k] |= static_cast<W>(static_cast<W>(bf16 ? bits[i] >> 16 : bits[i]) << shift);
          }
        if (bf16 && (low & 0xffffu) != 0) throw IoError("a field of bfloat16 codes holds another value");
      };
      if (narrow_words) {
        uint32_t* words = records_narrow.data();
        not_held |= f == Field::lo   ? narrow_field<Field::lo>(bits, record_count, words)
                    : f == Field::hi ? narrow_field<Field::hi>(bits, record_count, words)
                                     : narrow_field<Field::bound>(bits, record_count, words);
        continue;
      }
      switch (f) {
        case Field::lo: scatter(out.bounds, 0, true); break;
        case Field::hi: scatter(out.bounds, 16, true); break;
        case Field::bound: scatter(out.bounds, 32, false); break;
        case Field::exact_lo: scatter(out.exact, 0, true); break;
        case Field::exact_hi: scatter(out.exact, 16, true); break;
        case Field::w0: scatter(out.weights, 0, true); break;
        case Field::w1: scatter(out.weights, 16, true); break;
        case Field::w2: scatter(out.weights, 32, true); break;
        case Field::paper_lo: scatter(out.paper, 0, true); break;
        case Field::paper_hi: scatter(out.paper, 16, true); break;
        case Field::surplus: scatter(out.surplus, 0, true); break;
        case Field::values: break;
      }
    }
    if (p != end) throw IoError("trailing bytes after the last field");
  } catch (const IoError& e) {
    throw IoError(where + ": " + e.what());
  }
  if (narrow_words) {
    const uint32_t* words = records_narrow.data();
    for (uint32_t i = 0; i < record_count; ++i)
      not_held |= ((words[i] >> 8 & 0xffu) - (words[i] & 0xffu)) >> 31;  // hi < lo
    if (not_held != 0) throw IoError(where + ": " + kRecordNotHeld + " (corrupt brick)");
    for (uint32_t base = 0, i = 0; base < nodes; base += 8, i += 7) {  // over the record slots; the others 0
      narrow_words[base] = 0;
      std::copy_n(words + i, 7, narrow_words + base + 1);
    }
  }
}

}  // namespace isotope
