#include "io/store/field_codec.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <limits>
#include <optional>
#include <string>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "io/store/held_words.h"
#include "isotope/error.h"

namespace isotope {
namespace {

// Mode byte values and flag bits are part of the store format (docs/FORMAT.md).
constexpr uint8_t kModeConstant = 1, kModeInteger = 2, kModeFloat = 3;
constexpr uint8_t kIntegerHasInf = 1, kIntegerDelta = 2;  // integer flags; other bits must be 0
constexpr uint8_t kFloatPlanes = 1;                       // float flags; other bits must be 0
// Integer mode takes v when 2v is an integer with |2v| <= 2^30: codes, the +inf code just above
// them and their wrapped differences all stay within 32 bits.
constexpr float kMaxTwiceValue = 1 << 30;
constexpr uint32_t kInfBits = 0x7f800000u;

// Float fields go to byte planes when fewer than 1 in kRepeatRarity values repeats one of the
// kRepeatWindow before it (see planes_pay_off).
constexpr size_t kRepeatWindow = 8, kRepeatRarity = 50;

// ---- little-endian bytes, independent of the host's byte order ----

void put_u8(std::vector<uint8_t>& out, uint8_t v) { out.push_back(v); }
void put_u32(std::vector<uint8_t>& out, uint32_t v) {
  for (int b = 0; b < 4; ++b) out.push_back(static_cast<uint8_t>(v >> (8 * b)));
}
void put_u64(std::vector<uint8_t>& out, uint64_t v) {
  for (int b = 0; b < 8; ++b) out.push_back(static_cast<uint8_t>(v >> (8 * b)));
}

// Bounds-checked reads: every read names what it wanted when the bytes run out.
struct Reader {
  const uint8_t* p;
  const uint8_t* end;

  void need(size_t n, const char* what) const {
    if (static_cast<size_t>(end - p) < n)
      throw IoError(std::string("field codec: truncated ") + what + " (need " + std::to_string(n) + " bytes, have " +
                    std::to_string(end - p) + ")");
  }
  uint8_t u8(const char* what) {
    need(1, what);
    return *p++;
  }
  uint64_t le(int bytes, const char* what) {
    need(static_cast<size_t>(bytes), what);
    uint64_t v = 0;
    for (int b = 0; b < bytes; ++b) v |= uint64_t{p[b]} << (8 * b);
    p += bytes;
    return v;
  }
  uint32_t u32(const char* what) { return static_cast<uint32_t>(le(4, what)); }
  uint64_t u64(const char* what) { return le(8, what); }
  // The next n bytes, consumed.
  const uint8_t* take(size_t n, const char* what) {
    need(n, what);
    const uint8_t* start = p;
    p += n;
    return start;
  }
};

// ---- byte planes: byte b of every word together, so constant high bytes form long runs ----

// Appends words(i), i < n, as W byte planes.
template <int W, class WordOf>
void append_planes(size_t n, WordOf word_of, std::vector<uint8_t>& out) {
  const size_t start = out.size();
  out.resize(start + n * W);
  uint8_t* planes = out.data() + start;
  for (size_t i = 0; i < n; ++i) {
    const uint32_t w = word_of(i);
    for (int b = 0; b < W; ++b) planes[static_cast<size_t>(b) * n + i] = static_cast<uint8_t>(w >> (8 * b));
  }
}

// Appends words(i), i < n, as little-endian 4-byte words.
template <class WordOf>
void append_words(size_t n, WordOf word_of, std::vector<uint8_t>& out) {
  const size_t start = out.size();
  out.resize(start + n * 4);
  uint8_t* bytes = out.data() + start;
  for (size_t i = 0; i < n; ++i) {
    const uint32_t w = word_of(i);
    for (int b = 0; b < 4; ++b) bytes[4 * i + static_cast<size_t>(b)] = static_cast<uint8_t>(w >> (8 * b));
  }
}

template <int W>
uint32_t word_at(const uint8_t* planes, size_t n, size_t i) {
  uint32_t w = planes[i];
  if constexpr (W >= 2) w |= uint32_t{planes[n + i]} << 8;
  if constexpr (W == 4) w |= uint32_t{planes[2 * n + i]} << 16 | uint32_t{planes[3 * n + i]} << 24;
  return w;
}

// ---- constant: one bit pattern repeated (empty metadata intervals, all-zero errors) ----

bool is_constant(std::span<const float> values) {
  const uint32_t first = std::bit_cast<uint32_t>(values[0]);
  for (float v : values)
    if (std::bit_cast<uint32_t>(v) != first) return false;
  return true;
}

// ---- integer: codes v*m (m = 1, or 2 for half-integers), +inf as the code above all others ----

struct IntegerPlan {
  int32_t multiplier = 1;
  int32_t min_code = 0, max_code = 0;  // over the finite values
  bool has_inf = false;
};

// What plan_integer learns from some values: their codes' bounds (twice the values, over the
// finite ones), whether any is +inf or finite, and whether one is none of these.
struct IntegerScan {
  int32_t lo = std::numeric_limits<int32_t>::max(), hi = std::numeric_limits<int32_t>::min();
  uint32_t odd = 0, finite = 0, inf = 0, bad = 0;

  void add(float v) {
    const auto bits = std::bit_cast<uint32_t>(v);
    if (bits == kInfBits) {
      inf = 1;
      return;
    }
    const float twice = v * 2;                    // exact for every value that passes the range test
    if (!(std::fabs(twice) <= kMaxTwiceValue)) {  // also NaN and -inf
      bad = 1;
      return;
    }
    const auto c = static_cast<int32_t>(twice);
    if (static_cast<float>(c) != twice || (c == 0 && std::signbit(v))) bad = 1;
    odd |= static_cast<uint32_t>(c);
    lo = std::min(lo, c);
    hi = std::max(hi, c);
    finite = 1;
  }
};

#if defined(__SSE2__)
// IntegerScan four values at a time, without a branch, one lane each: every field of every brick
// a convert writes comes through here, and the compiler does not vectorize add() (SSE2 has no
// 32-bit min or max).
struct IntegerScan4 {
  __m128i lo = _mm_set1_epi32(std::numeric_limits<int32_t>::max());
  __m128i hi = _mm_set1_epi32(std::numeric_limits<int32_t>::min());
  __m128i odd = _mm_setzero_si128(), finite = _mm_setzero_si128(), inf = _mm_setzero_si128();
  __m128i good = _mm_set1_epi32(-1);  // per lane: every value so far +inf or a code

  void add(const float* p) {
    const __m128 v = _mm_loadu_ps(p);
    const __m128i bits = _mm_castps_si128(v);
    const __m128i is_inf = _mm_cmpeq_epi32(bits, _mm_set1_epi32(static_cast<int>(kInfBits)));
    const __m128 twice = _mm_add_ps(v, v);
    const __m128 in_range =
        _mm_cmple_ps(_mm_and_ps(twice, _mm_castsi128_ps(_mm_set1_epi32(0x7fffffff))), _mm_set1_ps(kMaxTwiceValue));
    const __m128i c = _mm_cvttps_epi32(_mm_and_ps(twice, in_range));
    const __m128i exact = _mm_castps_si128(_mm_and_ps(_mm_cmpeq_ps(_mm_cvtepi32_ps(c), twice), in_range));
    const __m128i negative_zero = _mm_and_si128(_mm_cmpeq_epi32(c, _mm_setzero_si128()), _mm_srai_epi32(bits, 31));
    good = _mm_and_si128(good, _mm_or_si128(is_inf, _mm_andnot_si128(negative_zero, exact)));
    inf = _mm_or_si128(inf, is_inf);
    finite = _mm_or_si128(finite, _mm_andnot_si128(is_inf, _mm_set1_epi32(-1)));
    const __m128i code = _mm_andnot_si128(is_inf, c);
    odd = _mm_or_si128(odd, code);
    const __m128i for_lo =
        _mm_or_si128(code, _mm_and_si128(is_inf, _mm_set1_epi32(std::numeric_limits<int32_t>::max())));
    const __m128i below = _mm_cmpgt_epi32(lo, for_lo);
    lo = _mm_or_si128(_mm_and_si128(below, for_lo), _mm_andnot_si128(below, lo));
    const __m128i for_hi =
        _mm_or_si128(code, _mm_and_si128(is_inf, _mm_set1_epi32(std::numeric_limits<int32_t>::min())));
    const __m128i above = _mm_cmpgt_epi32(for_hi, hi);
    hi = _mm_or_si128(_mm_and_si128(above, for_hi), _mm_andnot_si128(above, hi));
  }
  bool all_good() const { return _mm_movemask_epi8(good) == 0xffff; }
  // The four lanes folded into a scan of one value at a time.
  void fold_into(IntegerScan& scan) const {
    alignas(16) std::array<int32_t, 4> l, h, o, f, i;
    _mm_store_si128(reinterpret_cast<__m128i*>(l.data()), lo);
    _mm_store_si128(reinterpret_cast<__m128i*>(h.data()), hi);
    _mm_store_si128(reinterpret_cast<__m128i*>(o.data()), odd);
    _mm_store_si128(reinterpret_cast<__m128i*>(f.data()), finite);
    _mm_store_si128(reinterpret_cast<__m128i*>(i.data()), inf);
    for (size_t k = 0; k < 4; ++k) {
      scan.lo = std::min(scan.lo, l[k]);
      scan.hi = std::max(scan.hi, h[k]);
      scan.odd |= static_cast<uint32_t>(o[k]);
      scan.finite |= f[k] != 0;
      scan.inf |= i[k] != 0;
    }
  }
};
#endif

// Empty when some value is neither +inf nor an exactly representable (half-)integer code; -0.0
// is excluded because code 0 decodes to +0.0.
std::optional<IntegerPlan> plan_integer(std::span<const float> values) {
  IntegerScan scan;
  size_t i = 0;
#if defined(__SSE2__)
  // A field that is not integer-valued shows it within its first block.
  constexpr size_t kBlock = 256;
  IntegerScan4 lanes;
  while (i + 4 <= values.size()) {
    const size_t end = std::min(values.size() & ~size_t{3}, i + kBlock);
    for (; i < end; i += 4) lanes.add(values.data() + i);
    if (!lanes.all_good()) return std::nullopt;
  }
  lanes.fold_into(scan);
#endif
  for (; i < values.size(); ++i) scan.add(values[i]);
  if (scan.bad != 0 || scan.finite == 0) return std::nullopt;
  IntegerPlan plan;
  plan.multiplier = (scan.odd & 1) ? 2 : 1;
  const int shift = plan.multiplier == 2 ? 0 : 1;  // twice-values -> codes
  plan.min_code = scan.lo >> shift;
  plan.max_code = scan.hi >> shift;
  plan.has_inf = scan.inf != 0;
  return plan;
}

// Offsets o = code - min_code fit in W bytes (the width); deltas between neighbouring offsets
// are taken modulo 2^(8W) and zigzagged within W bytes, so both choices have the same width and a
// uint8 field stays one byte per value even where it jumps from 0 to 255.
template <int W>
constexpr uint32_t kWidthMask = W == 4 ? ~0u : (1u << (8 * W)) - 1;

template <int W>
uint32_t zigzag(uint32_t d) {  // d: a W-byte two's complement difference
  const uint32_t sign = d >> (8 * W - 1) & 1;
  return ((d << 1) ^ (0u - sign)) & kWidthMask<W>;
}
template <int W>
uint32_t unzigzag(uint32_t z) {
  return ((z >> 1) ^ (0u - (z & 1))) & kWidthMask<W>;
}

int width_of(uint32_t range) { return range <= 0xff ? 1 : range <= 0xffff ? 2 : 4; }

// Byte histograms of the W planes of one payload choice, to estimate its entropy-coded size.
template <int W>
struct PlaneHistograms {
  std::array<std::array<uint32_t, 256>, W> counts{};

  void add(uint32_t word) {
    for (int b = 0; b < W; ++b) ++counts[static_cast<size_t>(b)][word >> (8 * b) & 0xff];
  }
  void merge(const PlaneHistograms& o) {
    for (size_t b = 0; b < counts.size(); ++b)
      for (size_t v = 0; v < 256; ++v) counts[b][v] += o.counts[b][v];
  }
  // Order-0 entropy of all planes in bits, up to a term that depends on the value count alone.
  double bits() const {
    double sum = 0;
    for (const auto& plane : counts)
      for (uint32_t c : plane)
        if (c > 1) sum -= c * std::log2(static_cast<double>(c));
    return sum;
  }
};

// Smooth fields (values, ranges) give small deltas; sparse fields (errors that are mostly 0 with
// rare spikes) give smaller offsets, since a delta pays for every spike twice. zstd's Huffman
// stage sees the byte planes, so their order-0 entropy decides. On all fields of the shared uint8
// volumes (neghip, ironProt, bolt), bytes per voxel after zstd: deltas only 1.84/1.75/0.61,
// offsets only 1.84/1.69/0.55, summed bit lengths as the judge 1.76/1.67/0.58, entropy 1.73/1.65/0.57.
template <int W>
bool deltas_pay_off(size_t n, const uint32_t* offsets, const uint32_t* deltas) {
  // Four histograms of each, taken in turn: in a run of one value (most of a field) one counter
  // would take every increment, each waiting for the last.
  std::array<PlaneHistograms<W>, 4> delta_counts, offset_counts;
  for (size_t i = 0; i < n; ++i) {
    delta_counts[i & 3].add(deltas[i]);
    offset_counts[i & 3].add(offsets[i]);
  }
  for (size_t k = 1; k < 4; ++k) {
    delta_counts[0].merge(delta_counts[k]);
    offset_counts[0].merge(offset_counts[k]);
  }
  return delta_counts[0].bits() <= offset_counts[0].bits();
}

// Appends the integer header after the count, then W byte planes of offsets or of their deltas.
template <int W>
void append_integer(size_t n, const uint32_t* offsets, const IntegerPlan& plan, uint32_t min_code, uint32_t inf_code,
                    std::vector<uint8_t>& out) {
  // Each delta once, in a loop without a carry, which vectorizes: the choice reads them, and the
  // planes where they win.
  thread_local std::vector<uint32_t> delta_buffer;
  delta_buffer.resize(n);
  uint32_t* const deltas = delta_buffer.data();
  if (n > 0) deltas[0] = zigzag<W>(offsets[0]);
  for (size_t i = 1; i < n; ++i) deltas[i] = zigzag<W>(offsets[i] - offsets[i - 1]);
  const bool delta = deltas_pay_off<W>(n, offsets, deltas);
  put_u8(out, static_cast<uint8_t>(plan.multiplier));
  put_u8(out, static_cast<uint8_t>(W));
  put_u8(out, static_cast<uint8_t>((plan.has_inf ? kIntegerHasInf : 0) | (delta ? kIntegerDelta : 0)));
  put_u32(out, min_code);
  put_u32(out, inf_code);
  const uint32_t* const words = delta ? deltas : offsets;
  append_planes<W>(
      n, [words](size_t i) { return words[i]; }, out);
}

void encode_integer(std::span<const float> values, const IntegerPlan& plan, std::vector<uint8_t>& out) {
  const auto min_code = static_cast<uint32_t>(plan.min_code);
  const auto inf_code = static_cast<uint32_t>(plan.max_code + 1);
  const float m = static_cast<float>(plan.multiplier);
  const uint32_t range = (plan.has_inf ? inf_code : static_cast<uint32_t>(plan.max_code)) - min_code;
  const size_t n = values.size();
  // Each offset once: the choice between offsets and deltas, and the planes, read them again.
  // Four at a time where SSE2 is (the compiler vectorized no loop that branched on +inf, whose code
  // is the one above all others).
  thread_local std::vector<uint32_t> offsets;
  offsets.resize(n);
  const float* v = values.data();
  uint32_t* o = offsets.data();
  const uint32_t inf_offset = inf_code - min_code;
  size_t i = 0;
#if defined(__SSE2__)
  const __m128 m4 = _mm_set1_ps(m);
  const __m128i inf_bits4 = _mm_set1_epi32(static_cast<int>(kInfBits)),
                min4 = _mm_set1_epi32(static_cast<int>(min_code)),
                inf_offset4 = _mm_set1_epi32(static_cast<int>(inf_offset));
  for (; i + 4 <= n; i += 4) {
    const __m128 x = _mm_loadu_ps(v + i);
    const __m128i is_inf = _mm_cmpeq_epi32(_mm_castps_si128(x), inf_bits4);
    const __m128i code = _mm_cvttps_epi32(_mm_andnot_ps(_mm_castsi128_ps(is_inf), _mm_mul_ps(x, m4)));
    const __m128i offset = _mm_sub_epi32(code, min4);
    _mm_storeu_si128(reinterpret_cast<__m128i*>(o + i),
                     _mm_or_si128(_mm_and_si128(is_inf, inf_offset4), _mm_andnot_si128(is_inf, offset)));
  }
#endif
  for (; i < n; ++i) {
    const bool is_inf = std::bit_cast<uint32_t>(v[i]) == kInfBits;
    const auto code = static_cast<uint32_t>(static_cast<int32_t>(is_inf ? 0.0f : v[i] * m));
    o[i] = is_inf ? inf_offset : code - min_code;
  }
  switch (width_of(range)) {
    case 1: append_integer<1>(n, o, plan, min_code, inf_code, out); break;
    case 2: append_integer<2>(n, o, plan, min_code, inf_code, out); break;
    default: append_integer<4>(n, o, plan, min_code, inf_code, out); break;
  }
}

// The offsets of `count` one-byte zigzagged deltas that follow `offset`: their running sum modulo
// 256. Sixteen at a time where SSE2 is (every x86-64): the smooth fields of a uint8 store (values,
// ranges) are such deltas, and a sum within a register takes four shifted adds where a loop
// carries one add per value. Returns the last offset.
uint32_t running_bytes(const uint8_t* z, size_t count, uint32_t offset, uint8_t* out) {
  size_t i = 0;
#if defined(__SSE2__)
  const __m128i one = _mm_set1_epi8(1), low7 = _mm_set1_epi8(0x7f);
  __m128i carry = _mm_set1_epi8(static_cast<char>(offset));
  for (; i + 16 <= count; i += 16) {
    const __m128i w = _mm_loadu_si128(reinterpret_cast<const __m128i*>(z + i));
    // unzigzag: (z >> 1) ^ -(z & 1), in bytes
    __m128i d = _mm_xor_si128(_mm_and_si128(_mm_srli_epi16(w, 1), low7), _mm_cmpeq_epi8(_mm_and_si128(w, one), one));
    d = _mm_add_epi8(d, _mm_slli_si128(d, 1));
    d = _mm_add_epi8(d, _mm_slli_si128(d, 2));
    d = _mm_add_epi8(d, _mm_slli_si128(d, 4));
    d = _mm_add_epi8(d, _mm_slli_si128(d, 8));
    d = _mm_add_epi8(d, carry);
    _mm_storeu_si128(reinterpret_cast<__m128i*>(out + i), d);
    offset = static_cast<uint32_t>(_mm_extract_epi16(d, 7)) >> 8;
    carry = _mm_set1_epi8(static_cast<char>(offset));
  }
#endif
  for (; i < count; ++i) {
    offset = (offset + unzigzag<1>(z[i])) & kWidthMask<1>;
    out[i] = static_cast<uint8_t>(offset);
  }
  return offset;
}

// Two passes a block at a time: the codes (a running sum where deltas are stored, carried from
// value to value), then what the sink makes of them, a loop with no carry and no branch, so that it
// vectorizes (one loop that carries the sum and branches on +inf does not): every brick read
// decodes its values and records here. sink(first, code, count): the codes of values first ..
// first + count.
template <int W, bool Delta, class Sink>
void decode_codes(const uint8_t* planes, size_t n, uint32_t min_code, Sink& sink) {
  constexpr size_t kBlock = 512;
  uint32_t code[kBlock];
  uint32_t offset = 0;
  for (size_t first = 0; first < n; first += kBlock) {
    const size_t count = std::min(kBlock, n - first);
    if constexpr (W == 1 && Delta) {
      uint8_t run[kBlock];
      offset = running_bytes(planes + first, count, offset, run);
      for (size_t i = 0; i < count; ++i) code[i] = min_code + run[i];
    } else {
      for (size_t i = 0; i < count; ++i) {
        const uint32_t w = word_at<W>(planes, n, first + i);
        if constexpr (Delta) {
          offset = (offset + unzigzag<W>(w)) & kWidthMask<W>;
          code[i] = min_code + offset;
        } else {
          code[i] = min_code + w;
        }
      }
    }
    sink(first, code, count);
  }
}

// An integer field's header, after its count.
struct IntegerField {
  uint32_t multiplier = 1, width = 1, min_code = 0, inf_code = 0;
  bool has_inf = false, delta = false;
  const uint8_t* planes = nullptr;

  IntegerField(Reader& r, size_t n) {
    multiplier = r.u8("integer multiplier");
    if (multiplier != 1 && multiplier != 2)
      throw IoError("field codec: integer multiplier " + std::to_string(multiplier) + ", expected 1 or 2");
    width = r.u8("integer width");
    if (width != 1 && width != 2 && width != 4)
      throw IoError("field codec: integer width " + std::to_string(width) + ", expected 1, 2 or 4");
    const uint8_t flags = r.u8("integer flags");
    if (flags & ~(kIntegerHasInf | kIntegerDelta))
      throw IoError("field codec: unknown integer flags " + std::to_string(flags));
    has_inf = flags & kIntegerHasInf;
    delta = flags & kIntegerDelta;
    min_code = r.u32("integer minimum code");
    inf_code = r.u32("integer +inf code");
    planes = r.take(n * width, "integer payload");
  }
  uint32_t inf_mask() const { return has_inf ? ~0u : 0u; }  // a code of inf_code is +inf only in a field that has it

  template <class Sink>
  void decode(size_t n, Sink& sink) const {
    auto run = [&]<bool Delta>() {
      switch (width) {
        case 1: decode_codes<1, Delta>(planes, n, min_code, sink); break;
        case 2: decode_codes<2, Delta>(planes, n, min_code, sink); break;
        default: decode_codes<4, Delta>(planes, n, min_code, sink); break;
      }
    };
    delta ? run.template operator()<true>() : run.template operator()<false>();
  }
};

const uint8_t* decode_integer(Reader r, std::span<float> values) {
  const IntegerField field(r, values.size());
  const uint32_t inf_mask = field.inf_mask(), inf_code = field.inf_code;
  const float scale = field.multiplier == 2 ? 0.5f : 1.0f;
  float* const values_out = values.data();
  auto sink = [&](size_t first, const uint32_t* code, size_t count) {
    // Locals: the loop's stores cannot then alias what it reads, and it vectorizes.
    float* const out = values_out + first;
    const uint32_t mask = inf_mask, inf_at = inf_code;
    const float times = scale;
    for (size_t i = 0; i < count; ++i) {
      const uint32_t inf = (0u - static_cast<uint32_t>(code[i] == inf_at)) & mask;
      const auto bits = std::bit_cast<uint32_t>(static_cast<float>(static_cast<int32_t>(code[i])) * times);
      out[i] = std::bit_cast<float>((bits & ~inf) | (kInfBits & inf));
    }
  };
  field.decode(values.size(), sink);
  return r.p;
}

// The same values as bytes: code / multiplier, which must be an integer of 0..255 and not +inf.
const uint8_t* decode_integer(Reader r, std::span<uint8_t> bytes, uint32_t& bad) {
  const IntegerField field(r, bytes.size());
  const uint32_t inf_mask = field.inf_mask(), inf_code = field.inf_code, shift = field.multiplier == 2 ? 1 : 0;
  uint8_t* const bytes_out = bytes.data();
  auto sink = [&](size_t first, const uint32_t* code, size_t count) {
    uint8_t* const out = bytes_out + first;  // locals, as the floats' sink
    const uint32_t mask = inf_mask, inf_at = inf_code, by = shift;
    uint32_t wrong = 0;
    for (size_t i = 0; i < count; ++i) {
      const uint32_t c = code[i];
      wrong |= (c >> by & ~0xffu) | (c & by) | ((0u - static_cast<uint32_t>(c == inf_at)) & mask);
      out[i] = static_cast<uint8_t>(c >> by);
    }
    bad |= wrong;
  };
  field.decode(bytes.size(), sink);
  return r.p;
}

// ---- float: the bit patterns, as little-endian words or as four byte planes ----

// zstd finds exactly repeated values (saturated ranges and errors, quantized data) as 4-byte
// matches only in whole words; byte planes help where mantissas are noisy and nothing repeats.
// Measured on hydrogen, noise and algebraic fields with all their records: planes for every field
// cost 15.0/15.7/11.8 bytes per voxel after zstd, words 9.8/13.4/9.5, this choice 9.8/12.8/9.5.
bool planes_pay_off(std::span<const float> values) {
  size_t repeats = 0;
  for (size_t i = kRepeatWindow; i < values.size(); ++i) {
    const auto bits = std::bit_cast<uint32_t>(values[i]);
    bool seen = false;
    for (size_t lag = 1; lag <= kRepeatWindow; ++lag) seen |= std::bit_cast<uint32_t>(values[i - lag]) == bits;
    repeats += seen;
  }
  return repeats * kRepeatRarity < values.size();
}

void encode_float(std::span<const float> values, std::vector<uint8_t>& out) {
  const bool planes = planes_pay_off(values);
  put_u8(out, planes ? kFloatPlanes : 0);
  const auto bits_of = [&](size_t i) { return std::bit_cast<uint32_t>(values[i]); };
  if (planes) {
    append_planes<4>(values.size(), bits_of, out);
  } else {
    append_words(values.size(), bits_of, out);
  }
}

const uint8_t* decode_float(Reader r, std::span<float> values) {
  const uint8_t flags = r.u8("float flags");
  if (flags & ~kFloatPlanes) throw IoError("field codec: unknown float flags " + std::to_string(flags));
  const size_t n = values.size();
  const uint8_t* bytes = r.take(n * 4, "float payload");
  if (flags & kFloatPlanes) {
    for (size_t i = 0; i < n; ++i) values[i] = std::bit_cast<float>(word_at<4>(bytes, n, i));
  } else {
    for (size_t i = 0; i < n; ++i) {
      const uint8_t* b = bytes + 4 * i;
      values[i] =
          std::bit_cast<float>(uint32_t{b[0]} | uint32_t{b[1]} << 8 | uint32_t{b[2]} << 16 | uint32_t{b[3]} << 24);
    }
  }
  return r.p;
}

// A field's mode and count, checked against the count the caller expects.
uint8_t read_mode(Reader& r, size_t expected) {
  const uint8_t mode = r.u8("field mode");
  if (mode != kModeConstant && mode != kModeInteger && mode != kModeFloat)
    throw IoError("field codec: unknown field mode " + std::to_string(mode));
  const uint64_t count = r.u64("field count");
  if (count != expected)
    throw IoError("field codec: field holds " + std::to_string(count) + " values, expected " +
                  std::to_string(expected));
  return mode;
}

}  // namespace

FieldCoding encode_field(std::span<const float> values, std::vector<uint8_t>& out) {
  if (!values.empty() && is_constant(values)) {
    put_u8(out, kModeConstant);
    put_u64(out, values.size());
    put_u32(out, std::bit_cast<uint32_t>(values[0]));
    return FieldCoding::constant;
  }
  const std::optional<IntegerPlan> plan = values.empty() ? std::nullopt : plan_integer(values);
  put_u8(out, plan ? kModeInteger : kModeFloat);
  put_u64(out, values.size());
  if (!plan) {
    encode_float(values, out);
    return FieldCoding::bits;
  }
  encode_integer(values, *plan, out);
  return FieldCoding::integer;
}

const uint8_t* decode_field(const uint8_t* p, const uint8_t* end, std::span<float> values) {
  if (p == nullptr || end < p) throw IoError("field codec: no bytes to decode");
  Reader r{p, end};
  const uint8_t mode = read_mode(r, values.size());
  switch (mode) {
    case kModeConstant: {
      const float v = std::bit_cast<float>(r.u32("constant value"));
      for (float& x : values) x = v;
      return r.p;
    }
    case kModeInteger: return decode_integer(r, values);
    default: return decode_float(r, values);
  }
}

const uint8_t* decode_field(const uint8_t* p, const uint8_t* end, std::span<uint8_t> bytes) {
  if (p == nullptr || end < p) throw IoError("field codec: no bytes to decode");
  Reader r{p, end};
  const uint8_t mode = read_mode(r, bytes.size());
  uint32_t bad = 0;
  switch (mode) {
    case kModeConstant: {
      const uint8_t b = static_cast<uint8_t>(narrow_code(r.u32("constant value"), bad));
      std::fill(bytes.begin(), bytes.end(), b);
      break;
    }
    case kModeInteger: r.p = decode_integer(r, bytes, bad); break;
    default: {  // not what a one-byte store writes, but what its values may be
      thread_local std::vector<float> values;
      values.resize(bytes.size());
      r.p = decode_float(r, values);
      for (size_t i = 0; i < bytes.size(); ++i)
        bytes[i] = static_cast<uint8_t>(narrow_code(std::bit_cast<uint32_t>(values[i]), bad));
    }
  }
  return bad == 0 ? r.p : nullptr;
}

}  // namespace isotope
