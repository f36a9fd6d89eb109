// Pixel-space conditional UNet in the style of Imagen / DeepFloyd IF stage II:
// input concat(z_t, cond), timestep-conditioned residual blocks, self-attention
// at chosen levels, skip features that a Control Module can add residuals to.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <torch/torch.h>

#include "dn/nn/nn_blocks.h"
#include "dn/nn/prior.h"

namespace dn {

struct UNetConfig {
  int64_t in_channels = 3;    // z_t
  int64_t cond_channels = 3;  // conditioning image, concatenated to z_t
  int64_t out_channels = 3;
  // Default: small enough to train on 2 CPU cores (see bench/core_bench.cpp);
  // attention only at the coarsest level (1/8 resolution) and in the middle.
  int64_t base_channels = 32;
  std::vector<int64_t> channel_mults = {1, 2, 3, 4};  // one level per entry
  int64_t res_blocks = 1;                             // per encoder level (decoder: one more)
  std::vector<int64_t> attention_levels = {3};        // levels with self-attention
  bool middle_attention = true;
  int64_t head_channels = 32;
  int64_t norm_groups = 8;

  int64_t levels() const { return static_cast<int64_t>(channel_mults.size()); }
  int64_t embeddingChannels() const { return 4 * base_channels; }
  bool hasAttention(int64_t level) const;
  void validate() const;  // throws std::invalid_argument
};

// The encoder (input conv, down levels) and middle block. Skip features are the
// input conv output, every encoder res block output and every downsample output.
class UNetEncoder : public PriorEncoder {
 public:
  explicit UNetEncoder(const UNetConfig& config);
  EncoderFeatures encode(const torch::Tensor& z_t, const torch::Tensor& t,
                         const torch::Tensor& cond, const torch::Tensor& hint) override;
  std::vector<int64_t> skipChannels() const override { return skip_channels_; }
  int64_t middleChannels() const override;
  int64_t firstFeatureChannels() const override { return config_.base_channels; }

 private:
  struct Stage {  // one res block (plus attention) or one downsample
    nn::ResBlock res{nullptr};
    nn::AttentionBlock attention{nullptr};
    nn::Downsample down{nullptr};
  };
  UNetConfig config_;
  nn::TimestepMlp time_mlp_{nullptr};
  torch::nn::Conv2d input_conv_{nullptr};
  std::vector<Stage> stages_;
  nn::ResBlock middle1_{nullptr}, middle2_{nullptr};
  nn::AttentionBlock middle_attention_{nullptr};
  std::vector<int64_t> skip_channels_;
};

class UNet : public DenoisingPrior {
 public:
  explicit UNet(const UNetConfig& config);
  torch::Tensor predict(const torch::Tensor& z_t, const torch::Tensor& t, const torch::Tensor& cond,
                        const ControlResiduals* residuals = nullptr) override;
  std::shared_ptr<PriorEncoder> copyEncoder() override;
  int64_t sizeMultiple() const override { return int64_t(1) << (config_.levels() - 1); }
  const UNetConfig& config() const { return config_; }

 private:
  struct Stage {  // one res block (plus attention), optionally followed by an upsample
    nn::ResBlock res{nullptr};
    nn::AttentionBlock attention{nullptr};
    nn::Upsample up{nullptr};
  };
  UNetConfig config_;
  std::shared_ptr<UNetEncoder> encoder_;
  std::vector<Stage> stages_;
  torch::nn::GroupNorm out_norm_{nullptr};
  torch::nn::Conv2d out_conv_{nullptr};
};

// Copies every parameter and buffer of `from` into `to` by name; both must have
// identical structure (throws std::invalid_argument otherwise).
void copyWeights(const torch::nn::Module& from, torch::nn::Module& to);

int64_t parameterCount(const torch::nn::Module& module, bool trainable_only = false);

}  // namespace dn
