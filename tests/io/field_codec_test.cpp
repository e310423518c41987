// The field codec of the brick store: every bit survives (signed zeros, infinities, NaN payloads,
// denormals), integer fields shrink to their narrowest byte width, constant fields to one value,
// the byte layout is the one docs/FORMAT.md specifies, and hostile bytes (every truncation,
// random corruption) become an IoError, never a crash or a read outside the buffer.
#include "io/store/field_codec.h"

#include <gtest/gtest.h>
#include <zstd.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <functional>
#include <limits>
#include <memory>
#include <random>
#include <span>
#include <string>
#include <vector>

#include "io/volume/raw_reader.h"
#include "isotope/error.h"
#include "tests/support/io_error_of.h"

namespace isotope {
namespace {

using Bytes = std::vector<uint8_t>;
using Floats = std::vector<float>;
using testing::io_error_of;

// The mode byte that starts every field (docs/FORMAT.md, "Field encoding").
constexpr uint8_t kConstant = 1, kInteger = 2, kFloat = 3;
constexpr size_t kCommonHeader = 9, kConstantSize = 13, kIntegerHeader = 20, kFloatHeader = 10;
constexpr size_t kBrick = 32768;  // values in a 32^3 brick

const float kInf = std::numeric_limits<float>::infinity();

float from_bits(uint32_t b) { return std::bit_cast<float>(b); }

Bytes encode(const Floats& values) {
  Bytes out;
  encode_field(values, out);
  return out;
}

// Decodes from a heap block of exactly the encoded size, so that AddressSanitizer sees any read
// past the end; returns the values and checks that the whole encoding was consumed.
Floats decode(const Bytes& bytes, size_t count) {
  const auto block = std::make_unique<uint8_t[]>(bytes.size());
  std::copy(bytes.begin(), bytes.end(), block.get());
  Floats values(count);
  const uint8_t* end = decode_field(block.get(), block.get() + bytes.size(), values);
  EXPECT_EQ(end, block.get() + bytes.size()) << "decode did not consume the whole field";
  return values;
}

bool same_bits(const Floats& a, const Floats& b) {
  return a.size() == b.size() && std::equal(a.begin(), a.end(), b.begin(), [](float x, float y) {
           return std::bit_cast<uint32_t>(x) == std::bit_cast<uint32_t>(y);
         });
}

// Round trip; returns the encoding for checks of its mode and size.
Bytes expect_round_trip(const Floats& values) {
  const Bytes bytes = encode(values);
  EXPECT_TRUE(same_bits(decode(bytes, values.size()), values)) << values.size() << " values, mode " << int{bytes.at(0)};
  return bytes;
}

uint8_t mode_of(const Bytes& b) { return b.at(0); }
uint8_t integer_width(const Bytes& b) { return b.at(kCommonHeader + 1); }
uint8_t integer_multiplier(const Bytes& b) { return b.at(kCommonHeader); }

// 3-D coordinate of Morton index i (the store's order inside a brick).
std::array<int, 3> morton(uint32_t i) {
  std::array<int, 3> c{0, 0, 0};
  for (int b = 0; b < 10; ++b)
    for (int a = 0; a < 3; ++a) c[a] |= static_cast<int>((i >> (3 * b + a)) & 1) << b;
  return c;
}

std::array<float, 3> morton_point(uint32_t i) {
  const auto [x, y, z] = morton(i);
  return {static_cast<float>(x), static_cast<float>(y), static_cast<float>(z)};
}

// A smooth uint8-valued field in Morton order, like a brick of a CT scan.
Floats smooth_uint8(size_t n) {
  Floats v(n);
  for (size_t i = 0; i < n; ++i) {
    const auto [x, y, z] = morton_point(static_cast<uint32_t>(i));
    v[i] = std::round(127.5f + 120 * std::sin(x * 0.11f) * std::cos(y * 0.07f + z * 0.05f));
  }
  return v;
}

Floats uint16_ramp(size_t n) {
  Floats v(n);
  for (size_t i = 0; i < n; ++i) v[i] = static_cast<float>((i * 7 + i / 13) % 65536);
  return v;
}

// Error indicators of integer data: half-integers, and +inf, which the codec must keep.
Floats half_integers_with_inf(size_t n, uint32_t seed = 1) {
  std::mt19937 rng(seed);
  Floats v(n);
  for (size_t i = 0; i < n; ++i) v[i] = rng() % 9 == 0 ? kInf : static_cast<float>(rng() % 511) * 0.5f;
  return v;
}

Floats random_floats(size_t n, uint32_t seed = 2) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> d(-1000, 1000);
  Floats v(n);
  for (float& x : v) x = d(rng);
  return v;
}

Floats small_ints(size_t n, uint32_t seed = 3) {
  std::mt19937 rng(seed);
  Floats v(n);
  for (float& x : v) x = static_cast<float>(static_cast<int>(rng() % 21) - 10);
  return v;
}

// One example of every kind of field the tests encode, by name.
struct Kind {
  const char* name;
  std::function<Floats(size_t)> make;
};
const std::vector<Kind> kKinds = {
    {"smooth uint8", smooth_uint8},
    {"uint16 ramp", uint16_ramp},
    {"half-integers with +inf", [](size_t n) { return half_integers_with_inf(n); }},
    {"random floats", [](size_t n) { return random_floats(n); }},
    {"small ints", [](size_t n) { return small_ints(n); }},
    {"constant", [](size_t n) { return Floats(n, 42.0f); }},
};

size_t zstd_size(const Bytes& bytes) {
  Bytes dst(ZSTD_compressBound(bytes.size()));
  const size_t size = ZSTD_compress(dst.data(), dst.size(), bytes.data(), bytes.size(), 3);
  EXPECT_FALSE(ZSTD_isError(size));
  return size;
}

Bytes raw_bytes(const Floats& values) {
  Bytes b(values.size() * sizeof(float));
  std::memcpy(b.data(), values.data(), b.size());
  return b;
}

// ---- round trips ----

TEST(FieldCodecRoundTrip, EmptyFieldIsAFloatHeaderAlone) {
  const Bytes bytes = expect_round_trip({});
  EXPECT_EQ(mode_of(bytes), kFloat);
  EXPECT_EQ(bytes.size(), kFloatHeader);
}

TEST(FieldCodecRoundTrip, SingleValuesOfEveryKind) {
  for (float v :
       {0.0f, -0.0f, 1.0f, -7.0f, 0.5f, 3.25f, kInf, -kInf, from_bits(0x7fc00001u), from_bits(0x00000001u), 1e30f}) {
    const Bytes bytes = expect_round_trip({v});
    EXPECT_EQ(mode_of(bytes), kConstant) << v;  // one value is a constant field
  }
}

TEST(FieldCodecRoundTrip, ConstantFieldsKeepTheirExactBits) {
  for (uint32_t bits :
       {0x00000000u, 0x80000000u, 0x7f800000u, 0xff800000u, 0x7fc12345u, 0xffa00001u, 0x00000003u, 0x42280000u}) {
    const Bytes bytes = expect_round_trip(Floats(kBrick, from_bits(bits)));
    EXPECT_EQ(mode_of(bytes), kConstant) << std::hex << bits;
    EXPECT_EQ(bytes.size(), kConstantSize);
  }
}

TEST(FieldCodecRoundTrip, SmallIntegersUseOneByteWidth) {
  const Bytes bytes = expect_round_trip(small_ints(1000));
  EXPECT_EQ(mode_of(bytes), kInteger);
  EXPECT_EQ(integer_multiplier(bytes), 1);
  EXPECT_EQ(integer_width(bytes), 1);
}

TEST(FieldCodecRoundTrip, Uint16RangeRampStaysInteger) {
  const Bytes bytes = expect_round_trip(uint16_ramp(kBrick));
  EXPECT_EQ(mode_of(bytes), kInteger);
  EXPECT_LE(integer_width(bytes), 2);
  Floats full_range(70000);
  for (size_t i = 0; i < full_range.size(); ++i) full_range[i] = static_cast<float>(i % 65536);
  EXPECT_EQ(mode_of(expect_round_trip(full_range)), kInteger);
}

TEST(FieldCodecRoundTrip, HalfIntegersWithInfinityUseMultiplierTwo) {
  const Bytes bytes = expect_round_trip(half_integers_with_inf(kBrick));
  EXPECT_EQ(mode_of(bytes), kInteger);
  EXPECT_EQ(integer_multiplier(bytes), 2);
  EXPECT_EQ(integer_width(bytes), 2);  // codes 0..510 and +inf as 511
}

TEST(FieldCodecRoundTrip, InfinityBesidesTheLargestAndSmallestCodes) {
  const float big = 1 << 29;  // |2v| = 2^30, the largest integer-mode value
  for (const Floats& v : {Floats{kInf, 3, kInf}, Floats{-big, big, kInf, -big, kInf, big}, Floats{big, kInf, -big},
                          Floats{-0.5f, kInf, -big, 0.5f}}) {
    const Bytes bytes = expect_round_trip(v);
    EXPECT_EQ(mode_of(bytes), kInteger);
  }
}

TEST(FieldCodecRoundTrip, IntegersBeyondTwoToTheThirtyFallBackToFloat) {
  const float beyond = std::nextafter(float{1 << 29}, kInf);  // 2^29 + 64: 2v > 2^30
  for (const Floats& v : {Floats{1, 2, beyond}, Floats{1, 2, -beyond}, Floats{0, 3e9f, -3e9f, 1}, Floats{1, 2, 1e38f},
                          Floats{0.5f, beyond}, Floats{kInf, -beyond}}) {
    const Bytes bytes = expect_round_trip(v);
    EXPECT_EQ(mode_of(bytes), kFloat);
  }
}

TEST(FieldCodecRoundTrip, RandomFloatsUseFloatMode) {
  const Bytes bytes = expect_round_trip(random_floats(kBrick));
  EXPECT_EQ(mode_of(bytes), kFloat);
  EXPECT_EQ(bytes.size(), kFloatHeader + 4 * kBrick);
}

TEST(FieldCodecRoundTrip, RepeatingFloatsRoundTripAsWords) {
  Floats v(kBrick);
  for (size_t i = 0; i < v.size(); ++i) v[i] = 0.1f * static_cast<float>(i / 5);
  const Bytes bytes = expect_round_trip(v);
  EXPECT_EQ(mode_of(bytes), kFloat);
  EXPECT_EQ(bytes.at(kCommonHeader), 0);  // words, not byte planes
}

// A value that breaks integer mode anywhere in an integer field sends the field to float mode.
TEST(FieldCodecRoundTrip, SpecialValuesAmongIntegersKeepTheirBits) {
  const std::vector<uint32_t> specials = {0x80000000u,  // -0.0
                                          0xff800000u,  // -inf
                                          0x7fc00001u, 0xffc12345u, 0x7f800001u,
                                          0xffbfffffu,                             // NaNs, quiet and signalling
                                          0x00000001u, 0x807fffffu, 0x00400000u};  // denormals
  for (uint32_t bits : specials) {
    for (size_t at : {size_t{0}, size_t{17}, size_t{299}}) {
      Floats v = smooth_uint8(300);
      v[at] = from_bits(bits);
      const Bytes bytes = expect_round_trip(v);
      EXPECT_EQ(mode_of(bytes), kFloat) << std::hex << bits;
    }
  }
}

// The integer plan reads a field several values at a time: whatever decides it (a value that is no
// integer code, the least and largest codes, a half-integer, +inf) counts wherever it stands, in
// the first block of values, a later one, or the few left over at the end.
TEST(FieldCodecRoundTrip, WhatDecidesTheIntegerPlanCountsAtEveryPlace) {
  const std::vector<float> not_codes = {from_bits(0x80000000u), -kInf, from_bits(0x7fc00001u), 0.25f, -1.75f,
                                        1073741824.0f};  // -0.0, -inf, NaN, quarters, 2^30 (2v past 2^30)
  // The integer header after the count: multiplier, width, flags, then the least and +inf codes.
  auto code_at = [](const Bytes& b, size_t offset) {
    uint32_t c = 0;
    for (size_t k = 0; k < 4; ++k) c |= uint32_t{b.at(kCommonHeader + offset + k)} << (8 * k);
    return static_cast<int32_t>(c);
  };
  auto min_code = [&](const Bytes& b) { return code_at(b, 3); };
  auto inf_code = [&](const Bytes& b) { return code_at(b, 7); };  // the largest finite code + 1
  auto has_inf = [](const Bytes& b) { return (b.at(kCommonHeader + 2) & 1) != 0; };
  for (size_t n : {size_t{7}, size_t{257}, size_t{262}, size_t{263}, size_t{520}}) {
    const Floats base = smooth_uint8(n);  // codes 7..248
    for (size_t at = 0; at < n; ++at) {
      SCOPED_TRACE(std::to_string(n) + " values, at " + std::to_string(at));
      for (float x : not_codes) {
        Floats v = base;
        v[at] = x;
        EXPECT_EQ(mode_of(expect_round_trip(v)), kFloat) << x;
      }
      Floats low = base;
      low[at] = -300;
      const Bytes low_bytes = expect_round_trip(low);
      ASSERT_EQ(mode_of(low_bytes), kInteger);
      EXPECT_EQ(min_code(low_bytes), -300);
      EXPECT_EQ(integer_width(low_bytes), 2);  // codes -300..248
      Floats high = base;
      high[at] = 536870912.0f;  // 2v = 2^30: the largest that stays integer
      const Bytes high_bytes = expect_round_trip(high);
      ASSERT_EQ(mode_of(high_bytes), kInteger);
      EXPECT_EQ(integer_width(high_bytes), 4);
      EXPECT_EQ(inf_code(high_bytes), 536870913);
      EXPECT_FALSE(has_inf(high_bytes));
      Floats half = base;
      half[at] = 100.5f;
      const Bytes half_bytes = expect_round_trip(half);
      ASSERT_EQ(mode_of(half_bytes), kInteger);
      EXPECT_EQ(integer_multiplier(half_bytes), 2);
      Floats inf = base;
      inf[at] = kInf;
      const Bytes inf_bytes = expect_round_trip(inf);
      ASSERT_EQ(mode_of(inf_bytes), kInteger);
      EXPECT_EQ(integer_multiplier(inf_bytes), 1);
      EXPECT_TRUE(has_inf(inf_bytes));
      float largest = 0;  // of the finite values: +inf takes the code just above it
      for (size_t i = 0; i < n; ++i)
        if (i != at) largest = std::max(largest, base[i]);
      EXPECT_EQ(inf_code(inf_bytes), static_cast<int32_t>(largest) + 1);
    }
  }
}

TEST(FieldCodecRoundTrip, EverySizeFromOneToThreeHundredOfEveryKind) {
  for (const Kind& kind : kKinds)
    for (size_t n = 1; n <= 300; ++n) {
      SCOPED_TRACE(std::string(kind.name) + ", " + std::to_string(n) + " values");
      expect_round_trip(kind.make(n));
    }
}

TEST(FieldCodecRoundTrip, LargestBrickOfEveryKind) {
  for (const Kind& kind : kKinds) {
    SCOPED_TRACE(kind.name);
    expect_round_trip(kind.make(262144));
  }
}

TEST(FieldCodecRoundTrip, ConcatenatedFieldsDecodeOneAfterAnother) {
  const std::vector<Floats> fields = {
      smooth_uint8(500), Floats(500, 1.0f), random_floats(500), half_integers_with_inf(500), {}};
  Bytes all = {0xAB};  // encode_field appends: what is already there stays
  for (const Floats& f : fields) encode_field(f, all);
  EXPECT_EQ(all[0], 0xAB);
  const uint8_t* p = all.data() + 1;
  for (const Floats& f : fields) {
    Floats back(f.size());
    p = decode_field(p, all.data() + all.size(), back);
    EXPECT_TRUE(same_bits(back, f));
  }
  EXPECT_EQ(p, all.data() + all.size());
}

// Any payload bytes decode as the format defines them, value by value: offsets are the bytes'
// little-endian words across the W planes, or the running sum of their zigzagged deltas modulo
// 2^(8W); a code is the minimum plus the offset, +inf where the field has +inf and the code is
// its +inf code, else code x scale. Random bytes reach what smooth fields rarely do (deltas of
// 0x80 and more, codes equal to the +inf code in a field without +inf), at counts that end
// within a block of the decoder and within one of its sixteen-byte steps.
TEST(FieldCodecRoundTrip, AnyIntegerPayloadDecodesAsTheFormatDefinesIt) {
  std::mt19937 rng(2026);
  int64_t checked = 0;
  for (const uint8_t width : {uint8_t{1}, uint8_t{2}, uint8_t{4}})
    for (const uint8_t flags : {uint8_t{0}, uint8_t{1}, uint8_t{2}, uint8_t{3}})  // has +inf, delta
      for (const uint8_t multiplier : {uint8_t{1}, uint8_t{2}})
        for (const size_t n :
             {size_t{1}, size_t{15}, size_t{17}, size_t{511}, size_t{513}, size_t{1040}, size_t{4096}}) {
          // Codes within a few of the minimum, so that the +inf code (min + 3) recurs.
          const uint32_t min_code = static_cast<uint32_t>(rng() % 1000), inf_code = min_code + 3;
          Bytes bytes{kInteger};
          for (int b = 0; b < 8; ++b) bytes.push_back(static_cast<uint8_t>(uint64_t{n} >> (8 * b)));
          bytes.insert(bytes.end(), {multiplier, width, flags});
          for (const uint32_t v : {min_code, inf_code})
            for (int b = 0; b < 4; ++b) bytes.push_back(static_cast<uint8_t>(v >> (8 * b)));
          const size_t payload = bytes.size();
          for (size_t i = 0; i < n * width; ++i) bytes.push_back(static_cast<uint8_t>(rng() % 5 == 0 ? 3 : rng()));
          const Floats got = decode(bytes, n);
          const uint32_t mask = width == 4 ? ~0u : (1u << (8 * width)) - 1;
          uint32_t offset = 0;
          for (size_t i = 0; i < n; ++i) {
            uint32_t w = 0;
            for (int b = 0; b < width; ++b) w |= uint32_t{bytes[payload + static_cast<size_t>(b) * n + i]} << (8 * b);
            offset = (flags & 2) ? (offset + (((w >> 1) ^ (0u - (w & 1))) & mask)) & mask : w;
            const uint32_t code = min_code + offset;
            const float want = (flags & 1) && code == inf_code
                                   ? kInf
                                   : static_cast<float>(static_cast<int32_t>(code)) * (multiplier == 2 ? 0.5f : 1.0f);
            ASSERT_EQ(std::bit_cast<uint32_t>(got[i]), std::bit_cast<uint32_t>(want))
                << "width " << int{width} << ", flags " << int{flags} << ", multiplier " << int{multiplier}
                << ", count " << n << ", value " << i;
            ++checked;
          }
        }
  EXPECT_GT(checked, 0);
}

// ---- the byte layout of docs/FORMAT.md ----

// What encode_field says of a field is the mode it wrote (the store's encoder chooses zstd's
// parameters by it).
TEST(FieldCodecLayout, EncodeSaysWhichModeItWrote) {
  const auto coding = [](const Floats& values) {
    Bytes out;
    const FieldCoding c = encode_field(values, out);
    EXPECT_FALSE(out.empty());
    return std::pair{c, out.empty() ? uint8_t{0} : out[0]};
  };
  EXPECT_EQ(coding(Floats(100, 2.5f)), std::pair(FieldCoding::constant, kConstant));
  EXPECT_EQ(coding({1, 2, 3, 250, kInf}), std::pair(FieldCoding::integer, kInteger));
  EXPECT_EQ(coding({0.1f, 0.2f, 0.7f}), std::pair(FieldCoding::bits, kFloat));
  EXPECT_EQ(coding({}), std::pair(FieldCoding::bits, kFloat));
}

TEST(FieldCodecLayout, ConstantIsModeCountAndBits) {
  EXPECT_EQ(encode({2.0f, 2.0f}), (Bytes{1, 2, 0, 0, 0, 0, 0, 0, 0, 0x00, 0x00, 0x00, 0x40}));
}

TEST(FieldCodecLayout, SparseSpikesAreOffsetsFromTheMinimum) {
  // Offsets 0,0,0,5,0,0,0,5 have lower byte entropy than their deltas 0,0,0,10,9,0,0,10.
  EXPECT_EQ(encode({0, 0, 0, 5, 0, 0, 0, 5}), (Bytes{2, 8, 0, 0, 0, 0, 0, 0, 0,  // mode, count
                                                     1, 1, 0,                    // multiplier, width, flags
                                                     0, 0, 0, 0, 6, 0, 0, 0,     // min code, +inf code
                                                     0, 0, 0, 5, 0, 0, 0, 5}));
}

TEST(FieldCodecLayout, DeltasWrapWithinTheWidth) {
  // 0 -> 255 is -1 modulo 256: zigzag 1, so a uint8 field stays one byte wide.
  EXPECT_EQ(encode({0, 255, 255, 255, 255}), (Bytes{2, 5, 0, 0, 0, 0, 0, 0, 0,  //
                                                    1, 1, 2,                    // flags: delta
                                                    0, 0, 0, 0, 0, 1, 0, 0,     // +inf code 256
                                                    0, 1, 0, 0, 0}));
}

TEST(FieldCodecLayout, HalfIntegerDeltasWithInfinity) {
  // codes 1, 4 (+inf), 3 with m = 2: offsets 0, 3, 2, zigzag deltas 0, 6, 1.
  EXPECT_EQ(encode({0.5f, kInf, 1.5f}), (Bytes{2, 3, 0, 0, 0, 0, 0, 0, 0,  //
                                               2, 1, 3,                    // flags: has +inf | delta
                                               1, 0, 0, 0, 4, 0, 0, 0,     //
                                               0, 6, 1}));
}

TEST(FieldCodecLayout, WidthTwoDeltasInBytePlanes) {
  // offsets 0, 300, 301, 302, 303: zigzag deltas 0, 600, 2, 2, 2, low bytes first.
  EXPECT_EQ(encode({0, 300, 301, 302, 303}), (Bytes{2, 5,    0, 0, 0,    0, 0, 0, 0,  //
                                                    1, 2,    2,                       //
                                                    0, 0,    0, 0, 0x30, 1, 0, 0,     // +inf code 304
                                                    0, 0x58, 2, 2, 2,    0, 2, 0, 0, 0}));
}

TEST(FieldCodecLayout, FloatBytePlanesWhenNothingRepeats) {
  // 0.1f = 0x3dcccccd, -0.0f = 0x80000000: the low bytes of both, then the next bytes...
  EXPECT_EQ(encode({0.1f, -0.0f}), (Bytes{3, 2, 0, 0, 0, 0, 0, 0, 0,  //
                                          1,                          // flags: byte planes
                                          0xcd, 0, 0xcc, 0, 0xcc, 0, 0x3d, 0x80}));
}

TEST(FieldCodecLayout, FloatLittleEndianWordsWhenValuesRepeat) {
  const Bytes tenth = {0xcd, 0xcc, 0xcc, 0x3d}, minus_zero = {0, 0, 0, 0x80};
  Floats v;
  Bytes expected = {3, 9, 0, 0, 0, 0, 0, 0, 0, 0};  // flags: words
  for (int i = 0; i < 9; ++i) {                     // v[8] repeats v[6]
    v.push_back(i % 2 ? -0.0f : 0.1f);
    const Bytes& word = i % 2 ? minus_zero : tenth;
    expected.insert(expected.end(), word.begin(), word.end());
  }
  EXPECT_EQ(encode(v), expected);
}

// ---- sizes: what the codec buys before and after zstd ----

TEST(FieldCodecSize, SmoothUint8BrickIsOneBytePerValueBeforeZstd) {
  const Floats v = smooth_uint8(kBrick);
  const Bytes bytes = expect_round_trip(v);
  EXPECT_EQ(bytes.size(), kIntegerHeader + kBrick);
  EXPECT_LT(zstd_size(bytes) * 2, zstd_size(raw_bytes(v)));  // measured: 12114 against 27693 bytes
}

TEST(FieldCodecSize, ConstantBrickIsThirteenBytes) {
  EXPECT_EQ(encode(Floats(kBrick, 1.0f)).size(), kConstantSize);
  EXPECT_EQ(encode(Floats(262144, 0.0f)).size(), kConstantSize);
}

TEST(FieldCodecSize, HalfIntegerErrorsAreAtMostTwoBytesPerValue) {
  const Floats v = half_integers_with_inf(kBrick);
  const Bytes bytes = encode(v);
  EXPECT_EQ(bytes.size(), kIntegerHeader + 2 * kBrick);
  EXPECT_LT(zstd_size(bytes), zstd_size(raw_bytes(v)));
}

TEST(FieldCodecSize, FloatFieldsCompressNoWorseThanRawFloats) {
  Floats smooth(kBrick), repeating(kBrick);
  for (size_t i = 0; i < kBrick; ++i) {
    const auto [x, y, z] = morton_point(static_cast<uint32_t>(i));
    smooth[i] = std::sin(x * 0.1f) * std::cos(y * 0.13f) + 0.01f * z;
    repeating[i] = smooth[i / 8 * 8];
  }
  for (const Floats& v : {smooth, repeating}) EXPECT_LE(zstd_size(encode(v)), zstd_size(raw_bytes(v)) + 64);
}

// The values of a real uint8 scan, in 32^3 Morton bricks as the store keeps them.
TEST(FieldCodecSize, RealUint8ScanCompressesBelowHalfItsRawSize) {
  const std::string path = std::string(ISOTOPE_TEST_DATA) + "/neghip_66x66x66_uint8.raw";
  const Volume volume = read_raw(path, *parse_raw_name(path));
  size_t coded = 0, raw_floats = 0;
  for (int64_t bz = 0; bz < volume.dims[2]; bz += 32)
    for (int64_t by = 0; by < volume.dims[1]; by += 32)
      for (int64_t bx = 0; bx < volume.dims[0]; bx += 32) {
        Floats brick;
        for (uint32_t m = 0; m < kBrick; ++m) {
          const auto [x, y, z] = morton(m);
          if (bx + x < volume.dims[0] && by + y < volume.dims[1] && bz + z < volume.dims[2])
            brick.push_back(volume.at(bx + x, by + y, bz + z));
        }
        coded += zstd_size(expect_round_trip(brick));
        raw_floats += zstd_size(raw_bytes(brick));
      }
  const auto voxels = static_cast<double>(volume.node_count());
  EXPECT_LT(static_cast<double>(coded) / voxels, 0.4);  // measured 0.31 bytes per voxel
  EXPECT_LT(coded * 4, raw_floats * 3);                 // raw floats: 0.49
}

// ---- hostile bytes ----

std::vector<Floats> valid_fields() {
  Floats offsets(400, 0.0f), wide(400);
  for (size_t i = 0; i < 400; i += 37) offsets[i] = 9;
  for (size_t i = 0; i < wide.size(); ++i) wide[i] = static_cast<float>((i * 2654435761u) % 100000000);
  return {{},   Floats(400, 3.0f),  smooth_uint8(400),    uint16_ramp(400), offsets, half_integers_with_inf(400),
          wide, random_floats(400), Floats(400, 0.1f * 3)};
}

// Whether v is a byte's value: an integer of 0..255, and its very bits (not -0).
bool is_byte(float v) {
  return v >= 0.0f && v <= 255.0f &&
         std::bit_cast<uint32_t>(static_cast<float>(static_cast<int>(v))) == std::bit_cast<uint32_t>(v);
}

// decode_field into bytes (a one-byte store's values) agrees with it into floats on [p, end) for
// `count` values: the same refusal of malformed bytes, else the same end and the floats' bytes
// where every float is a byte's value, else null.
::testing::AssertionResult bytes_agree_with_floats(const uint8_t* p, const uint8_t* end, size_t count) {
  Floats floats(count);
  std::vector<uint8_t> bytes(count, 0xEE);
  const uint8_t *float_end = nullptr, *byte_end = nullptr;
  const auto refusal = [](const std::function<void()>& f) -> std::string {  // "" when taken
    try {
      f();
    } catch (const IoError& e) {
      return e.what();
    }
    return "";
  };
  const std::string refused = refusal([&] { float_end = decode_field(p, end, floats); });
  const std::string byte_refused = refusal([&] { byte_end = decode_field(p, end, std::span<uint8_t>(bytes)); });
  if (refused != byte_refused)
    return ::testing::AssertionFailure() << "floats: \"" << refused << "\", bytes: \"" << byte_refused << "\"";
  if (!refused.empty()) return ::testing::AssertionSuccess();
  const bool all_bytes = std::all_of(floats.begin(), floats.end(), is_byte);
  if (!all_bytes)
    return byte_end == nullptr ? ::testing::AssertionSuccess()
                               : ::testing::AssertionFailure() << "a value that is not a byte's was taken";
  if (byte_end != float_end) return ::testing::AssertionFailure() << "the byte decode ends elsewhere";
  for (size_t i = 0; i < count; ++i)
    if (bytes[i] != static_cast<uint8_t>(floats[i]))
      return ::testing::AssertionFailure() << "value " << i << ": " << int{bytes[i]} << " for " << floats[i];
  return ::testing::AssertionSuccess();
}

// A one-byte store's values decode straight into bytes (no floats in between): the floats' bytes
// for every kind of field, and null as soon as one value is not a byte's, wherever it stands and
// whatever mode, width and multiplier the field took for it.
TEST(FieldCodecBytes, DecodeAsTheFloatsAndRefuseWhatIsNotAByte) {
  std::vector<Floats> fields = valid_fields();
  fields.push_back(small_ints(kBrick));
  fields.push_back(smooth_uint8(kBrick));
  Floats all(256);
  for (size_t i = 0; i < all.size(); ++i) all[i] = static_cast<float>((i * 97) % 256);
  fields.push_back(all);
  fields.push_back(Floats(700, 255.0f));  // constant
  fields.push_back(Floats(700, 0.0f));
  int taken = 0, refused = 0;
  for (const float odd : {-0.0f, -1.0f, 0.5f, 255.5f, 256.0f, 300.0f, 70000.0f, kInf, -kInf,
                          std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::denorm_min()})
    for (const size_t at : {size_t{0}, size_t{1}, size_t{511}, size_t{512}, size_t{699}}) {
      Floats f = smooth_uint8(700);
      f[at] = odd;
      fields.push_back(f);
      fields.push_back(Floats(700, odd));
    }
  for (const Floats& f : fields) {
    const Bytes bytes = encode(f);
    ASSERT_TRUE(bytes_agree_with_floats(bytes.data(), bytes.data() + bytes.size(), f.size()))
        << f.size() << " values, mode " << int{mode_of(bytes)};
    (std::all_of(f.begin(), f.end(), is_byte) ? taken : refused)++;
  }
  EXPECT_GE(taken, 8);
  EXPECT_GE(refused, 100);
}

TEST(FieldCodecHostile, EveryTruncationThrows) {
  for (const Floats& field : valid_fields()) {
    const Bytes bytes = encode(field);
    for (size_t len = 0; len < bytes.size(); ++len) {
      const auto block = std::make_unique<uint8_t[]>(std::max<size_t>(len, 1));
      std::copy_n(bytes.begin(), len, block.get());
      Floats out(field.size());
      const std::string message = io_error_of([&] { decode_field(block.get(), block.get() + len, out); });
      ASSERT_NE(message.find("truncated"), std::string::npos) << len << " of " << bytes.size() << " bytes: " << message;
      ASSERT_TRUE(bytes_agree_with_floats(block.get(), block.get() + len, field.size()));
    }
  }
}

TEST(FieldCodecHostile, CountOtherThanTheCallersThrows) {
  const Bytes bytes = encode(smooth_uint8(100));
  for (size_t n : {0, 99, 101}) {
    Floats out(n);
    EXPECT_EQ(io_error_of([&] { decode_field(bytes.data(), bytes.data() + bytes.size(), out); }),
              "field codec: field holds 100 values, expected " + std::to_string(n));
  }
}

TEST(FieldCodecHostile, NullOrReversedRangeThrows) {
  Floats out(1);
  const uint8_t byte = 1;
  EXPECT_NE(io_error_of([&] { decode_field(nullptr, nullptr, out); }), "");
  EXPECT_NE(io_error_of([&] { decode_field(&byte + 1, &byte, out); }), "");
}

// Overwrites byte `at` of a valid encoding of `field` and returns the decoder's message.
std::string message_with(const Floats& field, size_t at, uint8_t value) {
  Bytes bytes = encode(field);
  bytes.at(at) = value;
  Floats out(field.size());
  return io_error_of([&] { decode_field(bytes.data(), bytes.data() + bytes.size(), out); });
}

TEST(FieldCodecHostile, UnknownModeWidthMultiplierOrFlagsAreNamed) {
  const Floats ints = smooth_uint8(100), floats = random_floats(100);
  EXPECT_EQ(message_with(ints, 0, 0), "field codec: unknown field mode 0");
  EXPECT_EQ(message_with(ints, 0, 4), "field codec: unknown field mode 4");
  EXPECT_EQ(message_with(ints, kCommonHeader, 3), "field codec: integer multiplier 3, expected 1 or 2");
  EXPECT_EQ(message_with(ints, kCommonHeader + 1, 3), "field codec: integer width 3, expected 1, 2 or 4");
  EXPECT_EQ(message_with(ints, kCommonHeader + 2, 4), "field codec: unknown integer flags 4");
  EXPECT_EQ(message_with(floats, kCommonHeader, 2), "field codec: unknown float flags 2");
}

TEST(FieldCodecHostile, BytesAfterTheFieldAreLeftToTheCaller) {
  Bytes bytes = encode(smooth_uint8(100));
  const size_t size = bytes.size();
  bytes.resize(size + 7, 0xEE);
  Floats out(100);
  EXPECT_EQ(decode_field(bytes.data(), bytes.data() + bytes.size(), out), bytes.data() + size);
}

// Random bit flips, overwritten bytes, cut and extended encodings: each decode either throws
// IoError or fills the values; anything else (a crash, a sanitizer report, another exception)
// fails. Run under -DISOTOPE_SANITIZE=address,undefined.
TEST(FieldCodecHostile, RandomCorruptionThrowsIoErrorOrDecodes) {
  std::mt19937 rng(20240601);
  const std::vector<Floats> fields = valid_fields();
  std::vector<Bytes> encodings;
  for (const Floats& f : fields) encodings.push_back(encode(f));
  int thrown = 0, decoded = 0;
  for (int iteration = 0; iteration < 20000; ++iteration) {
    const size_t which = rng() % fields.size();
    Bytes bytes = encodings[which];
    const auto pick = [&] { return bytes.empty() ? size_t{0} : rng() % bytes.size(); };
    switch (rng() % 4) {
      case 0:  // flip a few bits, mostly in the header
        for (int k = 1 + static_cast<int>(rng() % 3); k > 0; --k) {
          const size_t at = rng() % 2 ? rng() % std::min<size_t>(bytes.size(), kIntegerHeader) : pick();
          if (!bytes.empty()) bytes[at] ^= static_cast<uint8_t>(1u << (rng() % 8));
        }
        break;
      case 1:  // overwrite a few bytes
        for (int k = 1 + static_cast<int>(rng() % 4); k > 0; --k)
          if (!bytes.empty()) bytes[pick()] = static_cast<uint8_t>(rng());
        break;
      case 2: bytes.resize(pick()); break;                                            // cut
      default: bytes.resize(bytes.size() + rng() % 64, static_cast<uint8_t>(rng()));  // extend
    }
    const auto block = std::make_unique<uint8_t[]>(std::max<size_t>(bytes.size(), 1));
    std::copy(bytes.begin(), bytes.end(), block.get());
    // Mostly the true count (the caller knows it); sometimes a wrong one.
    Floats out(rng() % 8 ? fields[which].size() : rng() % 500);
    ASSERT_TRUE(bytes_agree_with_floats(block.get(), block.get() + bytes.size(), out.size()));
    try {
      const uint8_t* end = decode_field(block.get(), block.get() + bytes.size(), out);
      ASSERT_GE(end, block.get());
      ASSERT_LE(end, block.get() + bytes.size());
      ++decoded;
    } catch (const IoError&) {
      ++thrown;
    }
  }
  EXPECT_GT(thrown, 1000);
  EXPECT_GT(decoded, 1000);
}

}  // namespace
}  // namespace isotope
