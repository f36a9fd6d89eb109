// Where the networks run: a device name checked against what this LibTorch
// build and machine offer, so that a missing GPU is one clear error up front
// rather than a LibTorch exception in the middle of a denoise.
#pragma once

#include <torch/torch.h>

#include <string>

namespace dn {

// "cpu", "cuda" or "cuda:N". Throws std::invalid_argument naming what is
// missing: an unknown name, a LibTorch built without CUDA or no GPU visible,
// or a CUDA index past the devices present.
torch::Device parseDevice(const std::string& name);

// Throws std::invalid_argument unless tensors can be placed on `device`.
void checkDeviceAvailable(const torch::Device& device);

}  // namespace dn
