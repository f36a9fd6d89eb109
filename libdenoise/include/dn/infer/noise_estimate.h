// The Monte Carlo noise of a render, estimated from the render alone. The
// sample count is a poor proxy for it: at 4 spp a simple, directly lit scene
// can be as clean as a training frame at 100 spp, and at 16 spp a room lit
// through a window as noisy as one at 4 spp. Sampling must start where the forward
// noise covers the render's own (the trainer picks render-start timesteps the
// same way), and local mean matching must blur enough to average it out.
#pragma once

#include <torch/torch.h>

#include "dn/infer/frame_uploads.h"
#include "dn/io/buffers.h"

namespace dn {

// Feature-buffer residual above which a pixel sits on an edge or texture of its
// own (albedo and normals in [0, 1] / [-1, 1] units) and is left out.
constexpr double kFeatureEdge = 0.05;

// The feature buffers whose edges and texture the measurements leave out.
const std::vector<std::string>& noiseFeatureBuffers();

// Root mean square noise of `image` (1,C,H,W; the frame's radiance, in the
// space the noise is wanted in), from the high-pass residual of Immerkaer's 3x3
// operator, scaled so that independent noise of standard deviation s gives s
// and smooth gradients give 0. Pixels where the frame's albedo, normal or depth
// (those it has, normalized as the model sees them) have a residual above
// kFeatureEdge are left out, unless that leaves fewer than 5 % of the frame.
// Works in strips of rows: a 4K frame needs no full-frame temporaries.
double estimateNoise(const torch::Tensor& image, const FrameBuffers& frame);

// How much of its input's noise a denoiser left: the high-pass energy that
// estimateNoise measures, on the same flat pixels (all of them when under 5 %
// are flat), of its input and of its output (root of the sums; only their
// ratio means anything). OIDN's network
// removes independent per-pixel noise and leaves most of the noise of a pixel
// filter that splats samples, which correlates neighbours and looks like detail.
struct NoiseLeft {
  double input = 0, output = 0;
  double fraction() const { return input > 0 ? output / input : 0.0; }
};
// Images off the CPU are measured where they are (measureNoiseLeftByTensors).
NoiseLeft measureNoiseLeft(const torch::Tensor& input, const torch::Tensor& output,
                           const FrameBuffers& frame);
// The same with the features taken from `frame`'s uploads off the CPU
// (those the networks already sent are not sent again).
NoiseLeft measureNoiseLeft(const torch::Tensor& input, const torch::Tensor& output,
                           FrameUploads& frame);
// The same sums in tensor operations on the images' device, the features sent
// there and one small copy back: on a GPU, no frame-sized copy to the host and
// no loop over it. Agrees with the CPU's loops to float rounding.
NoiseLeft measureNoiseLeftByTensors(const torch::Tensor& input, const torch::Tensor& output,
                                    const FrameBuffers& frame);
// The same with the features from `frame`'s uploads (on the images' device).
NoiseLeft measureNoiseLeftByTensors(const torch::Tensor& input, const torch::Tensor& output,
                                    FrameUploads& frame);

// The fraction of the noise left above which it is taken for correlated
// (docs/dndenoise.md has the measurements). The base leaves at most 0.59 of
// independent noise on the evaluation renders (Cycles 3.4 and 5, Mitsuba with
// a box filter; 4 to 64 spp), 0.52 on clean 256-spp Cycles renders, and 0.54
// to 0.97 of Mitsuba's Gaussian-splatted noise, mostly above 0.75. Low-noise
// splatted renders below the threshold keep the base's result, as OIDN's.
constexpr double kCorrelatedNoiseLeft = 0.65;
bool correlatedNoiseLeft(const NoiseLeft& left);

}  // namespace dn
