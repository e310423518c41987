#include "io/store/store_histogram.h"

#include <algorithm>
#include <cmath>

namespace isotope {
namespace {

// Nodes of G_j inside the data box, per axis: coordinates 0, 2^j, ... below dims.
int64_t nodes_inside(const std::array<int64_t, 3>& dims, int j) {
  int64_t n = 1;
  for (const int64_t d : dims) n *= (d - 1) / (int64_t{1} << j) + 1;
  return n;
}

}  // namespace

ValueHistogram sample_histogram(const StoreReader& store, int bins, int64_t max_samples) {
  const StoreHeader& h = store.header();
  const StoreLayout& layout = store.layout();
  int j = 0;
  while (j < layout.lattice().k && nodes_inside(h.dims, j) > max_samples) ++j;
  ValueHistogram hist;
  hist.min = h.value_min;
  hist.max = h.value_max;
  hist.scale = j;
  hist.counts.assign(static_cast<size_t>(std::max(bins, 1)), 0);
  const Band& band = layout.band(j);
  const int64_t t = layout.brick_width();
  const double span = hist.max - hist.min;
  const double offset = h.quantize_bits > 0 ? h.value_offset : 0, scale = h.quantize_bits > 0 ? h.value_scale : 1;
  double sum = 0;
  std::vector<float> values(static_cast<size_t>(layout.brick_nodes()));
  std::vector<uint64_t> bounds(values.size());
  for (int64_t bz = 0; bz < band.bricks[2]; ++bz)
    for (int64_t by = 0; by < band.bricks[1]; ++by)
      for (int64_t bx = 0; bx < band.bricks[0]; ++bx) {
        const BrickView view{values.data(), bounds.data(), nullptr, nullptr, nullptr, nullptr};
        store.read_brick(layout.brick_index(j, {bx, by, bz}), {true, false, false, false}, view, values.data());
        for (size_t m = 0; m < values.size(); ++m) {
          const auto c = morton_decode(m);
          const std::array<int64_t, 3> node{(bx * t + c[0]) << j, (by * t + c[1]) << j, (bz * t + c[2]) << j};
          if (node[0] >= h.dims[0] || node[1] >= h.dims[1] || node[2] >= h.dims[2]) continue;
          const double v = offset + scale * values[m];
          const double at = span > 0 ? (v - hist.min) / span * static_cast<double>(hist.counts.size()) : 0;
          const auto bin = static_cast<size_t>(std::clamp(at, 0.0, static_cast<double>(hist.counts.size() - 1)));
          ++hist.counts[bin];
          sum += v;
          ++hist.sampled;
        }
      }
  hist.mean = hist.sampled > 0 ? sum / static_cast<double>(hist.sampled) : hist.min;
  return hist;
}

}  // namespace isotope
