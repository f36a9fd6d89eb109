// No non-finite value leaves a tool unless it was in the input: results are
// clamped to the largest finite value of the type they are written as.
#pragma once

#include <cmath>
#include <cstddef>
#include <limits>

#include "dn/image.h"

namespace dn::cli {

constexpr float kHalfMax = 65504.0f;
constexpr float kFloatMax = std::numeric_limits<float>::max();

// Values beyond +-limit (Inf included) become +-limit and NaN becomes 0 (the
// tools read non-finite input pixels as 0). Returns how many changed.
inline std::size_t clampToFinite(Image& image, float limit = kFloatMax) {
  std::size_t changed = 0;
  for (float& v : image.pixels) {
    if (std::abs(v) <= limit) continue;
    v = std::isnan(v) ? 0.0f : std::copysign(limit, v);
    ++changed;
  }
  return changed;
}

}  // namespace dn::cli
