#include "dn/nn/unet.h"

#include <algorithm>
#include <stdexcept>
#include <string>

namespace dn {

bool UNetConfig::hasAttention(int64_t level) const {
  return std::find(attention_levels.begin(), attention_levels.end(), level) !=
         attention_levels.end();
}

void UNetConfig::validate() const {
  auto require = [](bool ok, const std::string& what) {
    if (!ok) throw std::invalid_argument("invalid UNet config: " + what);
  };
  require(in_channels > 0 && cond_channels >= 0 && out_channels > 0, "channel counts must be > 0");
  require(base_channels > 0 && base_channels % 2 == 0, "base_channels must be even and > 0");
  require(!channel_mults.empty() && channel_mults.size() <= 8, "needs 1 to 8 channel multipliers");
  for (auto mult : channel_mults) require(mult > 0, "channel multipliers must be > 0");
  require(res_blocks >= 1, "res_blocks must be >= 1");
  for (auto level : attention_levels)
    require(level >= 0 && level < levels(), "attention level out of range");
  require(head_channels > 0 && norm_groups > 0, "head_channels and norm_groups must be > 0");
}

UNetEncoder::UNetEncoder(const UNetConfig& config) : config_(config) {
  config_.validate();
  const int64_t embedding = config_.embeddingChannels();
  const int64_t groups = config_.norm_groups;
  time_mlp_ = register_module("time_mlp", nn::TimestepMlp(config_.base_channels, embedding));
  input_conv_ = register_module(
      "input_conv",
      nn::conv3x3(config_.in_channels + config_.cond_channels, config_.base_channels));
  int64_t channels = config_.base_channels;
  skip_channels_.push_back(channels);
  for (int64_t level = 0; level < config_.levels(); ++level) {
    const int64_t out = config_.base_channels * config_.channel_mults[level];
    for (int64_t i = 0; i < config_.res_blocks; ++i) {
      const std::string name = "down" + std::to_string(level) + "_" + std::to_string(i);
      Stage stage;
      stage.res = register_module(name + "_res", nn::ResBlock(channels, out, embedding, groups));
      if (config_.hasAttention(level))
        stage.attention = register_module(name + "_attention",
                                          nn::AttentionBlock(out, config_.head_channels, groups));
      stages_.push_back(stage);
      channels = out;
      skip_channels_.push_back(channels);
    }
    if (level + 1 < config_.levels()) {
      Stage stage;
      stage.down =
          register_module("down" + std::to_string(level) + "_downsample", nn::Downsample(channels));
      stages_.push_back(stage);
      skip_channels_.push_back(channels);
    }
  }
  middle1_ = register_module("middle1", nn::ResBlock(channels, channels, embedding, groups));
  if (config_.middle_attention)
    middle_attention_ = register_module(
        "middle_attention", nn::AttentionBlock(channels, config_.head_channels, groups));
  middle2_ = register_module("middle2", nn::ResBlock(channels, channels, embedding, groups));
}

int64_t UNetEncoder::middleChannels() const {
  return config_.base_channels * config_.channel_mults.back();
}

EncoderFeatures UNetEncoder::encode(const torch::Tensor& z_t, const torch::Tensor& t,
                                    const torch::Tensor& cond, const torch::Tensor& hint) {
  EncoderFeatures features;
  features.embedding = time_mlp_->forward(t);
  const auto& embedding = features.embedding;
  auto input = config_.cond_channels > 0 ? torch::cat({z_t, cond}, 1) : z_t;
  auto h = input_conv_->forward(input);
  if (hint.defined()) h = h + hint;
  features.skips.push_back(h);
  for (auto& stage : stages_) {
    if (stage.down) {
      h = stage.down->forward(h);
    } else {
      h = stage.res->forward(h, embedding);
      if (stage.attention) h = stage.attention->forward(h);
    }
    features.skips.push_back(h);
  }
  h = middle1_->forward(h, embedding);
  if (middle_attention_) h = middle_attention_->forward(h);
  features.middle = middle2_->forward(h, embedding);
  return features;
}

UNet::UNet(const UNetConfig& config) : config_(config) {
  config_.validate();
  encoder_ = register_module("encoder", std::make_shared<UNetEncoder>(config_));
  const int64_t embedding = config_.embeddingChannels();
  const int64_t groups = config_.norm_groups;
  auto skip_channels = encoder_->skipChannels();
  int64_t channels = encoder_->middleChannels();
  for (int64_t level = config_.levels() - 1; level >= 0; --level) {
    const int64_t out = config_.base_channels * config_.channel_mults[level];
    for (int64_t i = 0; i <= config_.res_blocks; ++i) {
      const std::string name = "up" + std::to_string(level) + "_" + std::to_string(i);
      const int64_t in = channels + skip_channels.back();
      skip_channels.pop_back();
      Stage stage;
      stage.res = register_module(name + "_res", nn::ResBlock(in, out, embedding, groups));
      if (config_.hasAttention(level))
        stage.attention = register_module(name + "_attention",
                                          nn::AttentionBlock(out, config_.head_channels, groups));
      channels = out;
      if (level > 0 && i == config_.res_blocks)
        stage.up = register_module("up" + std::to_string(level) + "_upsample", nn::Upsample(out));
      stages_.push_back(stage);
    }
  }
  out_norm_ = register_module("out_norm", torch::nn::GroupNorm(torch::nn::GroupNormOptions(
                                              nn::groupCount(channels, groups), channels)));
  out_conv_ = register_module("out_conv", nn::conv3x3(channels, config_.out_channels));
  nn::zeroParameters(*out_conv_);
}

torch::Tensor UNet::predict(const torch::Tensor& z_t, const torch::Tensor& t,
                            const torch::Tensor& cond, const ControlResiduals* residuals) {
  auto features = encoder_->encode(z_t, t, cond, {});
  auto& skips = features.skips;
  auto h = features.middle;
  if (residuals) {
    TORCH_CHECK(residuals->skips.size() == skips.size() && residuals->middle.defined(),
                "control residuals do not match the prior's skip features");
    for (size_t i = 0; i < skips.size(); ++i) skips[i] = skips[i] + residuals->skips[i];
    h = h + residuals->middle;
  }
  for (auto& stage : stages_) {
    h = stage.res->forward(torch::cat({h, skips.back()}, 1), features.embedding);
    skips.pop_back();
    if (stage.attention) h = stage.attention->forward(h);
    if (stage.up) h = stage.up->forward(h);
  }
  return out_conv_->forward(torch::silu(out_norm_->forward(h)));
}

std::shared_ptr<PriorEncoder> UNet::copyEncoder() {
  auto copy = std::make_shared<UNetEncoder>(config_);
  copyWeights(*encoder_, *copy);
  return copy;
}

void copyWeights(const torch::nn::Module& from, torch::nn::Module& to) {
  torch::NoGradGuard no_grad;
  auto copy_all = [](const torch::OrderedDict<std::string, torch::Tensor>& source,
                     torch::OrderedDict<std::string, torch::Tensor> target) {
    if (source.size() != target.size())
      throw std::invalid_argument("cannot copy weights between modules of different structure");
    for (auto& item : target) {
      const torch::Tensor* value = source.find(item.key());
      if (!value || !value->sizes().equals(item.value().sizes()))
        throw std::invalid_argument("cannot copy weights: '" + item.key() + "' differs");
      item.value().copy_(*value);
    }
  };
  copy_all(from.named_parameters(), to.named_parameters());
  copy_all(from.named_buffers(), to.named_buffers());
}

int64_t parameterCount(const torch::nn::Module& module, bool trainable_only) {
  int64_t count = 0;
  for (const auto& parameter : module.parameters())
    if (!trainable_only || parameter.requires_grad()) count += parameter.numel();
  return count;
}

}  // namespace dn
