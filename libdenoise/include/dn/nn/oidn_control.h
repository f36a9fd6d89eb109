// The paper's Control Module over the pretrained OIDN base: a trainable copy of
// the base's encoder, fed what the base does not see (the light-path passes,
// depth and shader AOVs, which buffers are present, and in diffusion models the
// diffusion state and its noise level) through a small hint network, and
// zero-initialised 1x1 convolutions that turn the copy's features into
// residuals for the frozen base's decoder. At initialisation every residual is
// zero, so the controlled model returns exactly the base's output.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <torch/torch.h>

#include "dn/nn/nn_blocks.h"
#include "dn/nn/oidn_unet.h"

namespace dn {

struct OidnControlConfig {
  std::string input_set = "hdr_alb_nrm";  // the base network it steers (OidnInputSet name)
  // Canonical aux buffers the base does not see, in input order. Any of them
  // may be absent from a render: absent ones are zero with their flag off.
  std::vector<std::string> extra_buffers;
  int64_t hint_channels = 32;
  bool diffusion = false;  // inputs also hold the diffusion state (3) and its noise level (1)

  int64_t extraChannels() const;  // channels of the extra buffers alone
  // Channels of the hint input: extras, one presence flag per buffer, state, level.
  int64_t hintChannels() const;
  void validate() const;  // throws std::invalid_argument
};

// The trainable part.
class OidnControlImpl : public torch::nn::Module {
 public:
  // The encoder copy starts with `base`'s encoder weights.
  OidnControlImpl(const OidnControlConfig& config, OidnUNet& base);
  // baseInput: what the base sees (B, base channels, H, W); hint: (B, hintChannels, H, W).
  ControlResiduals forward(const torch::Tensor& baseInput, const torch::Tensor& hint);
  const OidnControlConfig& config() const { return config_; }

 private:
  OidnControlConfig config_;
  torch::nn::Sequential hint_{nullptr};
  OidnUNet copy_{nullptr};
  std::vector<nn::PointwiseConv> skipZeroConvs_;
  nn::PointwiseConv bottleneckZeroConv_{nullptr};
};
TORCH_MODULE(OidnControl);

// The frozen base (all its input sets, for renders without the control's
// buffers) and the Control Module that steers one of its networks. The base
// never gets gradients and stays in eval mode.
class OidnControlledImpl : public torch::nn::Module {
 public:
  OidnControlledImpl(OidnBase base, const OidnControlConfig& config);

  // The base's output steered by the control, in OIDN's output space.
  torch::Tensor forward(const torch::Tensor& baseInput, const torch::Tensor& hint);
  // The same with the base encoder's features computed once (diffusion steps).
  torch::Tensor decode(const OidnUNetImpl::Features& baseFeatures, const torch::Tensor& baseInput,
                       const torch::Tensor& hint);
  OidnUNet steered() const { return steered_; }  // the base network under control
  OidnBase base() const { return base_; }
  OidnControl control() const { return control_; }
  void train(bool on = true) override;

 private:
  OidnBase base_{nullptr};
  OidnUNet steered_{nullptr};
  OidnControl control_{nullptr};
};
TORCH_MODULE(OidnControlled);

}  // namespace dn
