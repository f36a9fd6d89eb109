// How render buffers become network inputs, shared by training and inference so
// both see exactly the same numbers. Every mapping is per pixel (no per-image
// statistics), so a tile of a frame is prepared exactly like the whole frame.
#pragma once

#include <string>
#include <vector>

#include <torch/torch.h>

#include "dn/io/buffers.h"  // defaultAuxBuffers(), FrameBuffers
#include "dn/tonemap.h"

namespace dn {

// How a buffer is normalized: light passes, emission and environment like
// radiance; albedo, colour passes and shader AOVs in [0, 1]; normals; depth; variances.
enum class AuxKind { Radiance, Unit, Normal, Depth, Variance };
AuxKind auxKind(const std::string& name);
// Depth in scene units -> [0, 1], log-compressed, saturating at 1000 units.
torch::Tensor normalizedDepth(const torch::Tensor& depth);

// Linear HDR radiance (B,3,H,W) -> model range [0, 1): clamp to [0, 6], then the curve.
torch::Tensor tonemapRadiance(const torch::Tensor& radiance, tonemap::Curve curve);
// The exact inverse on the way out (values clamped to the curve's range first).
torch::Tensor inverseTonemapRadiance(const torch::Tensor& tonemapped, tonemap::Curve curve);

// Aux buffers concatenated in `buffers` order (B,C,H,W) -> normalized inputs:
// light passes, emission and environment like radiance; albedo and colour
// passes and shader AOVs clamped to [0, 1]; normals clamped to [-1, 1]; depth
// log-compressed to [0, 1]; variances log-compressed.
torch::Tensor normalizeAux(const torch::Tensor& aux, const std::vector<std::string>& buffers,
                           tonemap::Curve curve);

// Total channel count of the named canonical buffers; throws on an unknown name.
int64_t auxChannelCount(const std::vector<std::string>& buffers);

// A rectangle of an image as a (1,C,height,width) float tensor (copied).
torch::Tensor imageRegionToTensor(const Image& image, int64_t y0, int64_t x0, int64_t height,
                                  int64_t width);
// (1,C,H,W) float tensor of an interleaved image, and back. A tensor off the
// CPU is laid out there and comes back through pinned memory.
torch::Tensor imageToTensor(const Image& image);
Image tensorToImage(const torch::Tensor& tensor);

// (1, C, H, W) float on `device`, the values of imageToTensor: on the CPU that
// tensor; elsewhere the stored floats copied there and laid out there.
torch::Tensor imageToDevice(const Image& image, torch::Device device);

// normalizeAux of the frame's `buffers` over one rectangle: the same numbers as
// normalizing the whole frame and cropping, but a frame's worth of aux channels
// (35 floats per pixel) never exists at once. Throws std::out_of_range naming a
// buffer the frame lacks.
// `exposure` scales the radiance buffers (variances by its square) first, as
// the colour is scaled by autoexposure.
torch::Tensor normalizedAuxRegion(const FrameBuffers& frame,
                                  const std::vector<std::string>& buffers, tonemap::Curve curve,
                                  int64_t y0, int64_t x0, int64_t height, int64_t width,
                                  double exposure = 1.0);

}  // namespace dn
