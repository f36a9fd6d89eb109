// An experiment kept beside the default pipeline: the pixel-space diffusion
// model trained from scratch here (models/diffusion-scratch.dnm, its own model
// card), run behind the same Pipeline interface. Radiance is exposed, clamped
// and tonemapped, the aux buffers normalized (dn/nn/model_inputs.h), the
// reverse diffusion run with the network applied in tiles, and the result
// inverse-tonemapped back to HDR, then corrected with the render's own
// evidence: its local means, its lights above the model's range, its black.
#pragma once

#include <memory>

#include "dn/diffusion/schedule.h"
#include "dn/infer/pipeline.h"
#include "dn/nn/model_file.h"

namespace dn {

// The largest tile chosen when DenoiseOptions::tile is 0.
constexpr int64_t kMaxDefaultTile = 256;

// Local mean matching radius of the model defaults, in pixels (dn/experiments/mean_match.h).
constexpr double kDefaultMeanMatchSigma = 2.0;

// Skip and mean matching radius for one input. A model's defaults are tuned for
// renders as noisy as its tuning frames; a render with less noise starts where
// the forward noise level matches its own (a later step) and trusts its local
// means at a proportionally smaller radius, a noisier one the other way.
// The render's noise relative to the tuning frames' (noiseScale) is
//  - its measured noise (dn/infer/noise_estimate.h) over the model's noise_reference,
//    when the model has one and no spp was given;
//  - else sqrt(default_spp / spp), from the sample count (Monte Carlo noise
//    falls as 1/sqrt(spp)), when the model has default_spp and the count is known;
//  - else 1: the defaults as they are.
// Explicit skip and radius win.
// The measured noiseScale is kept in [kMinNoiseScale, kMaxNoiseScale]: the shipped
// model fails when sampling starts near pure noise (docs/model-card-diffusion-scratch.md).
constexpr double kMinNoiseScale = 1.0 / 64.0;
constexpr double kMaxNoiseScale = 3.0;
SamplingPlan planSampling(const ModelInfo& info, const NoiseSchedule& schedule,
                          const ScratchSampling& sampling, int fileSpp, double renderNoise = -1);

// The frame's Monte Carlo noise in the model's space at `exposure` (0: the
// model's autoexposure), what planSampling compares with the model's noise_reference.
double measureModelNoise(const ModelInfo& info, const FrameBuffers& frame, double exposure = 0.0);

class ScratchDiffusionPipeline : public Pipeline {
 public:
  ScratchDiffusionPipeline(const ModelInfo& info, std::shared_ptr<ConditionalDenoiser> model);

  std::vector<std::string> missingBuffers(const std::vector<std::string>& available) const override;
  std::vector<std::string> usableBuffers(const std::vector<std::string>& available) const override;
  double bytesPerPixel() const override;
  DenoiseResult denoise(const FrameBuffers& frame, const DenoiseOptions& options) const override;

 private:
  ModelInfo info_;
  std::shared_ptr<ConditionalDenoiser> model_;
};

}  // namespace dn
