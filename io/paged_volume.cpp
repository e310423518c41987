#include "io/paged_volume.h"

#include "engine/adaptive_extract.h"

namespace isotope {

PagedVolume::PagedVolume(BrickCache& cache)
    : cache_(cache), layout_(cache.store().layout()), header_(cache.store().header()) {}

Mesh extract(const PagedVolume& volume, const ExtractOptions& options, ExtractStats* stats) {
  return extract_adaptive(volume, options, stats);
}

}  // namespace isotope
