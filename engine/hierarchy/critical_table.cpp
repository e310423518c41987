#include "engine/hierarchy/critical_table.h"

namespace isotope {

int critical_pattern_count(PolyhedronType type) {
  int n = 0;
  for (uint32_t p = 0; p < (1u << (ring_size(type) + 2)); ++p) n += is_critical_pattern(type, p) ? 1 : 0;
  return n;
}

int pattern_components(PolyhedronType type, uint32_t pattern) {
  return critical_table_internal::count_components(ring_size(type), pattern);
}

}  // namespace isotope
