// What the controlled OIDN model sees, built from tensors of linear buffers so
// that training and inference compute the same numbers: the base's input
// exactly as oidnInput makes it, and the Control Module's hint input.
#pragma once

#include <utility>

#include <torch/torch.h>

#include "dn/infer/tiler.h"
#include "dn/io/buffers.h"
#include "dn/nn/oidn_control.h"

namespace dn {

// OIDN's PU transfer function and its inverse, elementwise on CPU float tensors
// (NaN and negatives as 0 on the way in); puEncode takes any device (off the
// CPU the same formulas in tensor operations, to float rounding).
torch::Tensor puEncode(const torch::Tensor& radiance);
torch::Tensor puDecode(const torch::Tensor& encoded);

// (B, 3 * buffers, H, W): the set's buffers, linear, concatenated in its order;
// exposure (B) scales the colour. Equal to oidnInput on the same pixels.
torch::Tensor oidnBaseInput(const torch::Tensor& buffers, const OidnInputSet& set,
                            const torch::Tensor& exposure);

// OIDN's prefilter on a batch: linear albedo and normal (B, 3, H, W each)
// denoised by the base's "alb" and "nrm" networks, computed as runOidn does
// on a frame (sRGB albedo, mapped normals, padded to the alignment).
// (B, 6, H, W): the clean albedo, then the clean normal.
torch::Tensor cleanAux(const OidnBase& base, const torch::Tensor& albedo,
                       const torch::Tensor& normal);

// The hint input (B, config.hintChannels(), H, W): the extra buffers
// (B, config.extraChannels(), H, W, linear; light passes scaled by exposure and
// PU-encoded like the colour, colour passes clamped, depth log-compressed),
// their presence flags (B, buffers) as constant planes, and for diffusion
// models the state (B, 3, H, W, in the base's output space) and its noise level (B).
torch::Tensor controlHint(const OidnControlConfig& config, const torch::Tensor& extras,
                          const torch::Tensor& present, const torch::Tensor& exposure,
                          const torch::Tensor& state = {}, const torch::Tensor& sigma = {});
// controlHint in two parts, for a refinement that changes only the state: the
// extras and their flags, made once ...
torch::Tensor controlHintExtras(const OidnControlConfig& config, const torch::Tensor& extras,
                                const torch::Tensor& present, const torch::Tensor& exposure);
// ... and with each step's state (B, 3, H, W) and level (B) after them.
torch::Tensor withDiffusionState(const torch::Tensor& hintExtras, const torch::Tensor& state,
                                 const torch::Tensor& sigma);

// The extra buffers of a region of `frame` (zeros where absent) and their flags.
std::pair<torch::Tensor, torch::Tensor> frameExtras(const FrameBuffers& frame,
                                                    const OidnControlConfig& config,
                                                    const TileRect& region);
// The same over the whole frame on `device` (each buffer crossing as
// imageToDevice sends it): tiles take views of it.
std::pair<torch::Tensor, torch::Tensor> frameExtrasOnDevice(const FrameBuffers& frame,
                                                            const OidnControlConfig& config,
                                                            torch::Device device);

// The noise level as the hint network sees it (levels of a few hundredths).
constexpr double kSigmaInputScale = 10.0;

}  // namespace dn
