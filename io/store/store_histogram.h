#pragma once
// A histogram of a store's values for a user choosing an isovalue, from a sample that costs a
// fraction of a second on any store size: the nodes of the finest band (grid G_j, every 2^j-th
// node per axis) that has at most `max_samples` of them inside the data, read brick by brick.
#include <cstdint>
#include <vector>

#include "io/store/store_reader.h"

namespace isotope {

struct ValueHistogram {
  double min = 0, max = 0;      // the bins cover [min, max] (the store's value range)
  std::vector<int64_t> counts;  // equal bins
  int64_t sampled = 0;          // nodes counted
  int scale = 0;                // the band j sampled: every 2^j-th node per axis
  double mean = 0;              // of the sample
};

// Throws IoError naming a brick that cannot be read.
ValueHistogram sample_histogram(const StoreReader& store, int bins, int64_t max_samples);

}  // namespace isotope
