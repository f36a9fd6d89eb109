// The Monte Carlo noise of a render, estimated from the render alone. The
// sample count is a poor proxy for it: at 4 spp a simple, directly lit scene
// can be as clean as a training frame at 100 spp, and at 16 spp a room lit
// through a window as noisy as one at 4 spp. Sampling must start where the forward
// noise covers the render's own (the trainer picks render-start timesteps the
// same way), and local mean matching must blur enough to average it out.
#pragma once

#include <torch/torch.h>

#include "dn/io/buffers.h"

namespace dn {

// Feature-buffer residual above which a pixel sits on an edge or texture of its
// own (albedo and normals in [0, 1] / [-1, 1] units) and is left out.
constexpr double kFeatureEdge = 0.05;

// Root mean square noise of `image` (1,C,H,W; the frame's radiance, in the
// space the noise is wanted in), from the high-pass residual of Immerkaer's 3x3
// operator, scaled so that independent noise of standard deviation s gives s
// and smooth gradients give 0. Pixels where the frame's albedo, normal or depth
// (those it has, normalized as the model sees them) have a residual above
// kFeatureEdge are left out, unless that leaves fewer than 5 % of the frame.
// Works in strips of rows: a 4K frame needs no full-frame temporaries.
double estimateNoise(const torch::Tensor& image, const FrameBuffers& frame);

}  // namespace dn
