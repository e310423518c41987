#pragma once
// What the library's own faces see of a Source beyond its public interface: a store's reader, for
// the server's view of a store (its header, a histogram). Not installed.
#include "isotope/source.h"

namespace isotope {

class StoreReader;

namespace detail {

struct SourceAccess {
  // The store's reader; nullptr for a volume.
  static const StoreReader* store(const Source& source);
};

}  // namespace detail
}  // namespace isotope
