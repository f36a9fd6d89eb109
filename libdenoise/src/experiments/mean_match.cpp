#include "dn/experiments/mean_match.h"

#include <cmath>
#include <vector>

#include "dn/tonemap.h"

namespace dn {

namespace {

std::vector<double> gaussianKernel(double sigma) {
  const auto radius = static_cast<int64_t>(std::ceil(3.0 * sigma));
  std::vector<double> k;
  double sum = 0.0;
  for (int64_t x = -radius; x <= radius; ++x) {
    k.push_back(std::exp(-0.5 * (x / sigma) * (x / sigma)));
    sum += k.back();
  }
  for (auto& w : k) w /= sum;
  return k;
}

// One 1-D pass along `dim` of an image padded by the kernel radius on that axis.
// A sum of shifted slices: at 4K it needs half the temporary memory of conv2d.
torch::Tensor blurAlong(const torch::Tensor& padded, const std::vector<double>& k, int64_t dim) {
  const int64_t size = padded.size(dim) - static_cast<int64_t>(k.size()) + 1;
  auto out = padded.narrow(dim, 0, size) * k[0];
  for (std::size_t i = 1; i < k.size(); ++i)
    out.add_(padded.narrow(dim, static_cast<int64_t>(i), size), k[i]);
  return out;
}

// An isolated firefly (a pixel above all 8 of its neighbours) spread over the
// 5x5 pixels around it: the energy stays, the single bright pixel goes. At a
// mean matching radius under a pixel it would otherwise come back as a sparkle.
torch::Tensor spreadIsolated(const torch::Tensor& x) {
  namespace F = torch::nn::functional;
  const int64_t h = x.size(2), w = x.size(3);
  torch::Tensor excess;  // first the neighbours' maximum, then how far x exceeds it
  {
    const auto padded = F::pad(x, F::PadFuncOptions({1, 1, 1, 1}).mode(torch::kReplicate));
    for (int64_t dy = 0; dy < 3; ++dy)
      for (int64_t dx = 0; dx < 3; ++dx) {
        if (dy == 1 && dx == 1) continue;
        const auto shifted = padded.narrow(2, dy, h).narrow(3, dx, w);
        if (excess.defined())
          torch::maximum_out(excess, excess, shifted);
        else
          excess = shifted.clone();
      }
  }
  excess.sub_(x).neg_().clamp_min_(0.0);
  const auto spread = F::avg_pool2d(excess, F::AvgPool2dFuncOptions(5).stride(1).padding(2));
  return (x - excess).add_(spread);
}

}  // namespace

torch::Tensor gaussianBlur(const torch::Tensor& image, double sigma) {
  if (sigma <= 0.0) return image;
  namespace F = torch::nn::functional;
  const auto k = gaussianKernel(sigma);
  const auto r = static_cast<int64_t>(k.size() - 1) / 2;
  auto pad = [&](const torch::Tensor& x, std::vector<int64_t> sides) {
    return F::pad(x, F::PadFuncOptions(sides).mode(torch::kReplicate));
  };
  auto rows = blurAlong(pad(image, {r, r, 0, 0}), k, 3);
  return blurAlong(pad(rows, {0, 0, r, r}), k, 2);
}

torch::Tensor matchLocalMean(const torch::Tensor& denoised, const torch::Tensor& render,
                             double sigma, double maxRatio, double rangeMax) {
  if (sigma <= 0.0) return denoised;
  torch::NoGradGuard noGrad;
  // Dark regions: ratios of near-zero means are noise. Relative to the range, so
  // the correction does not depend on the exposure of the render.
  const double epsilon = 1e-3 * rangeMax / tonemap::kHdrMax;
  torch::Tensor targetMean;
  {  // the clamped render is not needed past its blur (4K: 100 MB a full-frame tensor)
    const auto target =
        spreadIsolated(torch::nan_to_num(render, 0.0, 0.0, 0.0).clamp_(0.0, rangeMax));
    targetMean = gaussianBlur(target, sigma);
  }
  auto resultMean = gaussianBlur(denoised.clamp_min(0.0), sigma);
  const auto ratio =
      (targetMean + epsilon).div_(resultMean + epsilon).clamp_(1.0 / maxRatio, maxRatio);
  // The ratio scales the result's detail; what it leaves of the local mean is
  // added, so the local mean is the render's everywhere. Where the ratio is
  // clamped (the network left a channel near 0 that the render has, or the
  // reverse) scaling alone left black or coloured specks.
  const auto offset = targetMean.sub_(resultMean.mul_(ratio));  // in place: two fewer frames
  return (denoised * ratio).add_(offset).clamp_min_(0.0);
}

}  // namespace dn
