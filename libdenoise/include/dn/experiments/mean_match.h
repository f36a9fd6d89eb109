// Local mean matching: a post-correction of the denoised image in linear HDR.
// Monte Carlo noise has zero mean in linear radiance, so a Gaussian-blurred
// render is an unbiased estimate of the blurred reference. The diffusion model
// works in a log-tonemapped range, where averaging noise pulls values down
// (Jensen's inequality), and its colours drift; rescaling every channel so its
// local mean matches the render's removes that low-frequency bias and keeps the
// model's detail.
#pragma once

#include <torch/torch.h>

#include "dn/tonemap.h"

namespace dn {

// Per-channel Gaussian blur (B,C,H,W) with standard deviation `sigma` pixels,
// edges replicated; sigma <= 0 returns the input.
torch::Tensor gaussianBlur(const torch::Tensor& image, double sigma);

// `denoised` (B,C,H,W, linear HDR) rescaled per channel by
// blur(render) / blur(denoised), the ratio clamped to [1/maxRatio, maxRatio],
// plus what the ratio leaves of blur(render) - blur(denoised) as an offset, so
// the local mean becomes the render's; the result is kept >= 0. Isolated
// fireflies of the render (a pixel above all 8 neighbours) are spread over 5x5
// first, their energy kept, so a sub-pixel sigma does not bring them back.
// The render is clamped to the model's radiance range [0, rangeMax] first, as the
// network saw it; NaN/Inf count as 0. sigma <= 0 returns `denoised` unchanged.
torch::Tensor matchLocalMean(const torch::Tensor& denoised, const torch::Tensor& render,
                             double sigma, double maxRatio = 4.0,
                             double rangeMax = tonemap::kHdrMax);

}  // namespace dn
