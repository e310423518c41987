#pragma once
// What a store is made with unless convert is told otherwise (docs/FORMAT.md): here alone, so that
// the library's layers and its faces read one value.

namespace isotope {

inline constexpr int kDefaultBrickBits = 4;  // bricks of 16^3 nodes

}  // namespace isotope
