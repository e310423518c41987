#pragma once
// What the traversal (traversal::Traversal) reads, as C++20 concepts: where values and records
// come from is the source's business, a hierarchy in memory (Hierarchy), the
// exact reference MultiresVolume (extract's InMemory) or a store paged through a brick
// cache (PagedVolume). The compiler names what a new source lacks.
#include <array>
#include <concepts>
#include <cstdint>

#include "engine/extract/options.h"
#include "engine/hierarchy/lattice.h"
#include "engine/hierarchy/record.h"

namespace isotope {

namespace traversal {

// A lattice node packed as x | y << 21 | z << 42: a tetrahedron is 32 bytes, and the midpoint
// of an edge is (p + q) >> 1, since each component of p + q is even and no carry crosses a field.
using Packed = uint64_t;
constexpr int kFieldBits = 21;
constexpr Packed kFieldMask = (Packed{1} << kFieldBits) - 1;
inline Packed pack(const Coord& c) {
  return static_cast<Packed>(c[0]) | static_cast<Packed>(c[1]) << kFieldBits |
         static_cast<Packed>(c[2]) << (2 * kFieldBits);
}
inline Coord unpack(Packed p) {
  return {static_cast<int64_t>(p & kFieldMask), static_cast<int64_t>((p >> kFieldBits) & kFieldMask),
          static_cast<int64_t>(p >> (2 * kFieldBits))};
}

}  // namespace traversal

// A reader of node values, one per task, used by one thread at a time: value(c, j) as
// MultiresVolume::value, where c lies on G_j (the multiples of 2^j), a hint for paged sources.
template <class R>
concept ValueReader = requires(R& r, const Coord& c, int band) {
  { r.value(c, band) } -> std::convertible_to<float>;
};

// A reader that also holds the records: locate(v) finds where the record of refinement vertex v
// lives (a handle is located once per visit and read twice at most, so a source spends its
// address arithmetic once); bounds() gives its range and error bound (and the surplus if `read`
// names it), topology() its critical intervals and weights (those `read` names); prefetch() is a
// hint that bounds() will be asked for soon.
template <class R>
concept RecordReader = ValueReader<R> &&
    requires(R& r, traversal::Packed v, const typename R::Handle& h, const RecordFields& read) {
  { r.locate(v) } -> std::convertible_to<typename R::Handle>;
  { r.bounds(h, read) } -> std::convertible_to<DiamondBounds>;
  { r.topology(h, read) } -> std::convertible_to<DiamondTopology>;
  r.prefetch(h);
};

// A reader that can fill a block of finest nodes at once (lo .. lo + n inclusive, x fastest, rows
// `stride` apart); false when it cannot, and the caller reads value by value.
template <class R>
concept BlockReader = requires(R& r, const Coord& lo, const std::array<int64_t, 3>& n, float* f, int64_t stride) {
  { r.block_values(lo, n, f, stride) } -> std::convertible_to<bool>;
};

// The shape of the grid and a reader per task: what eps = 0 needs (extract_finest).
template <class S>
concept ValueSource = requires(const S& s) {
  { s.lattice() } -> std::same_as<const Lattice&>;  // a reference: the traversal keeps it
  { s.data_dims() } -> std::convertible_to<const std::array<int64_t, 3>&>;
  { s.origin() } -> std::convertible_to<const std::array<double, 3>&>;
  { s.spacing() } -> std::convertible_to<const std::array<double, 3>&>;
  { s.reader() } -> ValueReader;
};

// What the adaptive traversal needs: records too, and how stored codes map to data values (a
// quantized store: value_offset + value_scale * code, with error_fold, the rounding, added to every
// error before it is compared).
template <class S>
concept TraversalSource = ValueSource<S> && requires(const S& s) {
  { s.reader() } -> RecordReader;
  { s.value_offset() } -> std::convertible_to<double>;
  { s.value_scale() } -> std::convertible_to<double>;
  { s.error_fold() } -> std::convertible_to<double>;
};

// A source that keeps what it reads under a budget may be told that what comes next will be read
// twice (a triangle budget's search, then the extraction at the eps it chose), so that it keeps
// all it may from the start.
template <class S>
concept RereadHint = requires(const S& s) {
  s.will_read_again();
};

}  // namespace isotope
