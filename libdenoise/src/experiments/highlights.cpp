#include "dn/experiments/highlights.h"

#include <algorithm>
#include <cmath>

namespace dn {

torch::Tensor restoreHighlights(const torch::Tensor& denoised, const torch::Tensor& render,
                                double rangeMax) {
  torch::NoGradGuard noGrad;
  namespace F = torch::nn::functional;
  const auto clean = torch::nan_to_num(render, 0.0, 0.0, 0.0);
  const auto peak = std::get<0>(clean.max(1, true));
  auto pool = [](const torch::Tensor& x) {
    return F::max_pool2d(x, F::MaxPool2dFuncOptions(3).stride(1).padding(1));
  };
  // Erosion (min over 3x3) rejects isolated fireflies; the dilation after it
  // brings back the highlight's border pixels.
  const auto bright = -pool(-peak) >= rangeMax;
  // A thin highlight (a specular line, a lamp's rim) fails the erosion, but
  // there the network itself answered "as bright as I can say": its result is
  // at the top of the range, where a removed firefly's is not.
  const auto saturated =
      (peak >= rangeMax) & (std::get<0>(denoised.max(1, true)) >= kSaturated * rangeMax);
  const auto keep = (pool(bright.to(torch::kFloat)) > 0.5) | saturated;
  if (!keep.any().item<bool>()) return denoised;
  return torch::where(keep, torch::maximum(clean, denoised), denoised);
}

torch::Tensor keepBlack(const torch::Tensor& denoised, const torch::Tensor& render,
                        int64_t window) {
  torch::NoGradGuard noGrad;
  namespace F = torch::nn::functional;
  const auto peak = std::get<0>(torch::nan_to_num(render, 0.0).max(1, true));
  const auto black =
      F::max_pool2d(peak, F::MaxPool2dFuncOptions(window).stride(1).padding(window / 2)) <= 0;
  return torch::where(black, torch::zeros_like(denoised), denoised);
}

int64_t blackWindow(int spp) {
  const double pixels = double(kBlackEvidenceSamples) / (spp > 0 ? spp : 4);
  const auto side = static_cast<int64_t>(std::ceil(std::sqrt(pixels)));
  return std::max<int64_t>(3, side % 2 ? side : side + 1);
}

}  // namespace dn
