// Shared by the LibTorch tests: the smallest UNet the checks need, and random
// weights (zero-initialised layers would make every output 0).
#pragma once

#include <ATen/CPUGeneratorImpl.h>
#include <torch/torch.h>

#include <cstdint>

#include "dn/nn/unet.h"

inline dn::UNetConfig tinyUNetConfig() {
  dn::UNetConfig config;
  config.base_channels = 8;
  config.channel_mults = {1, 2};
  config.res_blocks = 1;
  config.attention_levels = {1};
  config.head_channels = 8;
  config.norm_groups = 4;
  return config;
}

// Every parameter ~ N(0, scale^2), from a generator seeded with `seed`.
inline void randomize(torch::nn::Module& module, uint64_t seed, double scale) {
  torch::NoGradGuard no_grad;
  auto generator = at::detail::createCPUGenerator(seed);
  for (auto& parameter : module.parameters())
    parameter.copy_(torch::randn(parameter.sizes(), generator, torch::kFloat) * scale);
}
