#include "dn/nn/control_module.h"

#include <stdexcept>
#include <string>

#include "dn/nn/nn_blocks.h"

namespace dn {

void ControlConfig::validate() const {
  if (aux_channels < 0 || radiance_channels < 0 || aux_channels + radiance_channels == 0)
    throw std::invalid_argument("invalid control config: no input channels");
  if (hint_channels <= 0 || hint_layers < 1)
    throw std::invalid_argument(
        "invalid control config: hint_channels and hint_layers must be > 0");
}

ControlModule::ControlModule(const ControlConfig& config, std::shared_ptr<PriorEncoder> encoder)
    : config_(config), encoder_(std::move(encoder)) {
  config_.validate();
  hint_ = torch::nn::Sequential();
  int64_t channels = config_.aux_channels + config_.radiance_channels;
  for (int64_t i = 0; i < config_.hint_layers; ++i) {
    hint_->push_back(nn::conv3x3(channels, config_.hint_channels));
    hint_->push_back(torch::nn::SiLU());
    channels = config_.hint_channels;
  }
  auto hint_out = nn::conv3x3(channels, encoder_->firstFeatureChannels());
  nn::zeroParameters(*hint_out);
  hint_->push_back(hint_out);
  register_module("hint", hint_);
  register_module("encoder", encoder_);
  const auto skips = encoder_->skipChannels();
  for (size_t i = 0; i < skips.size(); ++i) {
    auto conv = nn::PointwiseConv(skips[i], skips[i]);
    nn::zeroParameters(*conv);
    skip_zero_convs_.push_back(register_module("zero_conv" + std::to_string(i), conv));
  }
  middle_zero_conv_ =
      register_module("middle_zero_conv",
                      nn::PointwiseConv(encoder_->middleChannels(), encoder_->middleChannels()));
  nn::zeroParameters(*middle_zero_conv_);
}

ControlResiduals ControlModule::forward(const torch::Tensor& z_t, const torch::Tensor& t,
                                        const torch::Tensor& cond, const torch::Tensor& aux) {
  std::vector<torch::Tensor> inputs;
  if (config_.radiance_channels > 0) inputs.push_back(cond);
  if (config_.aux_channels > 0) {
    TORCH_CHECK(aux.defined() && aux.size(1) == config_.aux_channels, "control module expects ",
                config_.aux_channels, " aux channels");
    inputs.push_back(aux);
  }
  auto hint = hint_->forward(torch::cat(inputs, 1));
  auto features = encoder_->encode(z_t, t, cond, hint);
  ControlResiduals residuals;
  for (size_t i = 0; i < features.skips.size(); ++i)
    residuals.skips.push_back(skip_zero_convs_[i]->forward(features.skips[i]));
  residuals.middle = middle_zero_conv_->forward(features.middle);
  return residuals;
}

ControlledDenoiser::ControlledDenoiser(std::shared_ptr<DenoisingPrior> base,
                                       const ControlConfig& config)
    : base_(std::move(base)) {
  control_ = std::make_shared<ControlModule>(config, base_->copyEncoder());
  register_module("base", base_);
  register_module("control", control_);
  for (auto& parameter : base_->parameters()) parameter.set_requires_grad(false);
  base_->eval();
}

torch::Tensor ControlledDenoiser::forward(const torch::Tensor& z_t, const torch::Tensor& t,
                                          const torch::Tensor& cond, const torch::Tensor& aux) {
  auto residuals = control_->forward(z_t, t, cond, aux);
  return base_->predict(z_t, t, cond, &residuals);
}

void ControlledDenoiser::train(bool on) {
  torch::nn::Module::train(on);
  base_->eval();
}

}  // namespace dn
