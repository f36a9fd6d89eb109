// The paper's Control Module (ControlNet-style): input convolutions over the
// auxiliary buffers and the noisy radiance whose output joins a trainable copy of
// the base encoder at its first feature map; zero-initialised 1x1 convolutions
// turn every copy feature into a residual for the frozen base's decoder.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include <torch/torch.h>

#include "dn/nn/nn_blocks.h"
#include "dn/nn/prior.h"

namespace dn {

struct ControlConfig {
  int64_t aux_channels = 0;       // auxiliary buffer channels (the paper uses 39)
  int64_t radiance_channels = 3;  // the noisy radiance, also fed to the hint convs
  int64_t hint_channels = 32;     // width of the input convolutions
  int64_t hint_layers = 3;        // input convolutions before the zero conv (>= 1)
  void validate() const;          // throws std::invalid_argument
};

class ControlModule : public torch::nn::Module {
 public:
  // `encoder` is the trainable copy of the base encoder (DenoisingPrior::copyEncoder).
  ControlModule(const ControlConfig& config, std::shared_ptr<PriorEncoder> encoder);
  ControlResiduals forward(const torch::Tensor& z_t, const torch::Tensor& t,
                           const torch::Tensor& cond, const torch::Tensor& aux);
  const ControlConfig& config() const { return config_; }

 private:
  ControlConfig config_;
  torch::nn::Sequential hint_{nullptr};
  std::shared_ptr<PriorEncoder> encoder_;
  std::vector<nn::PointwiseConv> skip_zero_convs_;
  nn::PointwiseConv middle_zero_conv_{nullptr};
};

// Frozen base prior + trainable Control Module. The base's parameters never get
// gradients and the base stays in eval mode whatever train() is called with.
class ControlledDenoiser : public ConditionalDenoiser {
 public:
  ControlledDenoiser(std::shared_ptr<DenoisingPrior> base, const ControlConfig& config);
  torch::Tensor forward(const torch::Tensor& z_t, const torch::Tensor& t, const torch::Tensor& cond,
                        const torch::Tensor& aux) override;
  int64_t sizeMultiple() const override { return base_->sizeMultiple(); }
  void train(bool on = true) override;

  std::shared_ptr<DenoisingPrior> base() const { return base_; }
  std::shared_ptr<ControlModule> control() const { return control_; }

 private:
  std::shared_ptr<DenoisingPrior> base_;
  std::shared_ptr<ControlModule> control_;
};

}  // namespace dn
