// Highlights above the model's range. The network sees radiance clamped to
// [0, kHdrMax] (after exposure), so lights, sun and sky brighter than that come
// out clipped. Where the render is above the range over a whole 3x3
// neighbourhood, or where the network's own result is clipped too, the pixel is
// a real highlight (an isolated firefly the network removed is not) and the
// render's value wins; at that brightness its relative noise is small.
#pragma once

#include <torch/torch.h>

namespace dn {

// Where the result is within 2 % of the top of the range it is taken as clipped.
constexpr double kSaturated = 0.98;

// `denoised` and `render` (B,3,H,W, linear HDR, same units); returns `denoised`,
// except the larger of the two where the render's channel maximum stays at or
// above `rangeMax` over the 3x3 neighbourhood of the pixel or of one of its
// neighbours (so highlight borders count too), or where both the render and the
// result (its channel maximum, at kSaturated) reach the range at the pixel.
// NaN/Inf in the render count as 0.
torch::Tensor restoreHighlights(const torch::Tensor& denoised, const torch::Tensor& render,
                                double rangeMax);

// The other end of the range: where the render is exactly black (every channel
// <= 0) over the window x window neighbourhood of a pixel, every path there
// returned nothing, so the result is black too rather than the faint haze the
// network leaves on black backgrounds. NaN in the render counts as black, Inf
// as light.
torch::Tensor keepBlack(const torch::Tensor& denoised, const torch::Tensor& render, int64_t window);

// How many zero samples make a region black: a dim region at 4 spp has zeros
// over many pixels by chance.
constexpr int kBlackEvidenceSamples = 512;

// The smallest odd window (at least 3) whose pixels hold kBlackEvidenceSamples
// samples at `spp`; an unknown count (0) is taken as 4.
int64_t blackWindow(int spp);

}  // namespace dn
