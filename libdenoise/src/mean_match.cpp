#include "dn/mean_match.h"

#include <cmath>

#include "dn/tonemap.h"

namespace dn {

namespace {

torch::Tensor gaussianKernel(double sigma) {
  const auto radius = static_cast<int64_t>(std::ceil(3.0 * sigma));
  auto x = torch::arange(-radius, radius + 1, torch::kFloat64);
  auto k = torch::exp(-0.5 * (x / sigma).pow(2));
  return (k / k.sum()).to(torch::kFloat32);
}

}  // namespace

torch::Tensor gaussianBlur(const torch::Tensor& image, double sigma) {
  if (sigma <= 0.0) return image;
  namespace F = torch::nn::functional;
  const int64_t channels = image.size(1);
  const auto k = gaussianKernel(sigma).to(image.dtype());
  const int64_t radius = (k.size(0) - 1) / 2;
  // Separable: rows, then columns; one group per channel.
  auto horizontal = k.view({1, 1, 1, -1}).expand({channels, 1, 1, k.size(0)});
  auto vertical = k.view({1, 1, -1, 1}).expand({channels, 1, k.size(0), 1});
  auto x =
      F::pad(image, F::PadFuncOptions({radius, radius, radius, radius}).mode(torch::kReplicate));
  x = F::conv2d(x, horizontal, F::Conv2dFuncOptions().groups(channels));
  return F::conv2d(x, vertical, F::Conv2dFuncOptions().groups(channels));
}

torch::Tensor matchLocalMean(const torch::Tensor& denoised, const torch::Tensor& render,
                             double sigma, double maxRatio) {
  if (sigma <= 0.0) return denoised;
  torch::NoGradGuard noGrad;
  constexpr double kEpsilon = 1e-3;  // dark regions: ratios of near-zero means are noise
  const auto target = torch::nan_to_num(render, 0.0, 0.0, 0.0).clamp(0.0, tonemap::kHdrMax);
  auto ratio = (gaussianBlur(target, sigma) + kEpsilon) /
               (gaussianBlur(denoised.clamp_min(0.0), sigma) + kEpsilon);
  return denoised * ratio.clamp(1.0 / maxRatio, maxRatio);
}

}  // namespace dn
