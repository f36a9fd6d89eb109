// Interfaces between the diffusion samplers/trainer and the networks. The frozen
// base prior is a DenoisingPrior, so a larger pretrained pixel-space model can
// replace the UNet trained here, as long as it exposes a trainable copy of its
// encoder and accepts residuals on its skip features. Also a ConditionalDenoiser
// run through the samplers (dn/diffusion/sampler.h) or as one regression pass.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include <torch/torch.h>

#include "dn/diffusion/sampler.h"

namespace dn {

// One residual per decoder skip feature (in encoder order) and one for the
// middle-block output; the prior adds them before its decoder.
struct ControlResiduals {
  std::vector<torch::Tensor> skips;
  torch::Tensor middle;
};

// What an encoder hands to a decoder: every skip feature, the middle output and
// the timestep embedding.
struct EncoderFeatures {
  std::vector<torch::Tensor> skips;
  torch::Tensor middle;
  torch::Tensor embedding;
};

// The encoder and middle block of a prior. `hint`, if defined, is added to the
// first feature map (ControlNet's hint injection).
class PriorEncoder : public torch::nn::Module {
 public:
  virtual EncoderFeatures encode(const torch::Tensor& z_t, const torch::Tensor& t,
                                 const torch::Tensor& cond, const torch::Tensor& hint) = 0;
  virtual std::vector<int64_t> skipChannels() const = 0;
  virtual int64_t middleChannels() const = 0;
  virtual int64_t firstFeatureChannels() const = 0;
};

// A conditional diffusion model: predicts (eps, v or x0) from z_t, the model
// timestep t (B) and the conditioning image cond = the noisy render.
class DenoisingPrior : public torch::nn::Module {
 public:
  virtual torch::Tensor predict(const torch::Tensor& z_t, const torch::Tensor& t,
                                const torch::Tensor& cond,
                                const ControlResiduals* residuals = nullptr) = 0;
  // A new, trainable encoder with a copy of this prior's encoder weights.
  virtual std::shared_ptr<PriorEncoder> copyEncoder() = 0;
  // Height and width must be multiples of this.
  virtual int64_t sizeMultiple() const = 0;
};

// What samplers and the trainer call: a denoiser that may use auxiliary buffers
// (aux may be undefined when it uses none). forward needs sizes that are
// multiples of sizeMultiple(); predict pads any size and crops back.
class ConditionalDenoiser : public torch::nn::Module {
 public:
  virtual torch::Tensor forward(const torch::Tensor& z_t, const torch::Tensor& t,
                                const torch::Tensor& cond, const torch::Tensor& aux) = 0;
  virtual int64_t sizeMultiple() const = 0;
  torch::Tensor predict(const torch::Tensor& z_t, const torch::Tensor& t, const torch::Tensor& cond,
                        const torch::Tensor& aux);
};

// A prior on its own as a ConditionalDenoiser (pretraining, and the "no control" ablation).
class PriorDenoiser : public ConditionalDenoiser {
 public:
  explicit PriorDenoiser(std::shared_ptr<DenoisingPrior> prior);
  torch::Tensor forward(const torch::Tensor& z_t, const torch::Tensor& t, const torch::Tensor& cond,
                        const torch::Tensor& aux) override;
  int64_t sizeMultiple() const override { return prior_->sizeMultiple(); }
  std::shared_ptr<DenoisingPrior> prior() const { return prior_; }

 private:
  std::shared_ptr<DenoisingPrior> prior_;
};

// The regression ablation's single pass (model space): the network sees the
// noisy render as both z_t and cond at timestep 0 and outputs x0 directly.
torch::Tensor regressDirect(ConditionalDenoiser& model, const torch::Tensor& cond,
                            const torch::Tensor& aux);

// Denoises tonemapped renders (B,3,H,W) in [0,1] with aux buffers (B,C,H,W) or
// an undefined tensor; returns the tonemapped result in [0,1].
torch::Tensor denoiseTonemapped(ConditionalDenoiser& model, const NoiseSchedule& schedule,
                                Prediction prediction, const torch::Tensor& radiance,
                                const torch::Tensor& aux, const SamplerOptions& options);

}  // namespace dn
