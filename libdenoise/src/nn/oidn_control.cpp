#include "dn/nn/oidn_control.h"

#include <stdexcept>

#include "dn/io/buffers.h"

namespace dn {

int64_t OidnControlConfig::extraChannels() const {
  int64_t channels = 0;
  for (const auto& name : extra_buffers) {
    const BufferSpec* spec = findBufferSpec(name);
    if (!spec) throw std::invalid_argument("unknown buffer '" + name + "' in the control's inputs");
    channels += spec->channels;
  }
  return channels;
}

int64_t OidnControlConfig::hintChannels() const {
  return extraChannels() + int64_t(extra_buffers.size()) + (diffusion ? 4 : 0);
}

void OidnControlConfig::validate() const {
  const OidnInputSet& set = oidnInputSet(input_set);
  for (const auto& name : extra_buffers)
    for (const auto& seen : set.buffers)
      if (name == seen)
        throw std::invalid_argument("'" + name + "' is an input of the base, not an extra buffer");
  if (hint_channels < 1) throw std::invalid_argument("hint_channels must be at least 1");
  if (hintChannels() < 1)
    throw std::invalid_argument("a Control Module needs extra buffers or a diffusion state");
}

OidnControlImpl::OidnControlImpl(const OidnControlConfig& config, OidnUNet& base)
    : config_(config) {
  config_.validate();
  OidnUNetConfig copyConfig = base->config();
  copyConfig.encoder_only = true;
  copy_ = register_module("copy", OidnUNet(copyConfig));
  {
    torch::NoGradGuard noGrad;
    const auto baseParams = base->named_parameters();
    for (auto& p : copy_->named_parameters()) p.value().copy_(baseParams[p.key()]);
  }
  // The hint network's last convolution starts at zero like the output ones, so
  // the copy first sees exactly the base's input (ControlNet's hint injection).
  const int64_t h = config_.hint_channels;
  auto hintOut = nn::conv3x3(h, copyConfig.in_channels);
  nn::zeroParameters(*hintOut);
  hint_ = register_module(
      "hint", torch::nn::Sequential(nn::conv3x3(config_.hintChannels(), h), torch::nn::ReLU(),
                                    nn::conv3x3(h, h), torch::nn::ReLU(), hintOut));
  const auto skips = base->skipChannels();
  for (size_t i = 0; i < skips.size(); ++i) {
    auto conv = nn::PointwiseConv(skips[i], skips[i]);
    nn::zeroParameters(*conv);
    skipZeroConvs_.push_back(register_module("zero_conv" + std::to_string(i), conv));
  }
  const int64_t b = base->bottleneckChannels();
  bottleneckZeroConv_ = register_module("bottleneck_zero_conv", nn::PointwiseConv(b, b));
  nn::zeroParameters(*bottleneckZeroConv_);
}

ControlResiduals OidnControlImpl::forward(const torch::Tensor& baseInput,
                                          const torch::Tensor& hint) {
  const auto features = copy_->encode(baseInput + hint_->forward(hint));
  ControlResiduals residuals;
  for (size_t i = 0; i < skipZeroConvs_.size(); ++i)
    residuals.skips.push_back(skipZeroConvs_[i]->forward(features.skips[i]));
  residuals.middle = bottleneckZeroConv_->forward(features.bottleneck);
  return residuals;
}

OidnControlledImpl::OidnControlledImpl(OidnBase base, const OidnControlConfig& config)
    : base_(register_module("base", std::move(base))) {
  steered_ = base_->net(config.input_set);
  for (auto& p : base_->parameters()) p.set_requires_grad(false);
  control_ = register_module("control", OidnControl(config, steered_));
  base_->eval();
}

torch::Tensor OidnControlledImpl::forward(const torch::Tensor& baseInput,
                                          const torch::Tensor& hint) {
  return decode(steered_->encode(baseInput), baseInput, hint);
}

torch::Tensor OidnControlledImpl::decode(const OidnUNetImpl::Features& baseFeatures,
                                         const torch::Tensor& baseInput,
                                         const torch::Tensor& hint) {
  const ControlResiduals residuals = control_->forward(baseInput, hint);
  return steered_->decode(baseFeatures, &residuals);
}

void OidnControlledImpl::train(bool on) {
  torch::nn::Module::train(on);
  base_->eval();
}

}  // namespace dn
