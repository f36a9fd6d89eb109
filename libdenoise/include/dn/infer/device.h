// Where the networks run: a device name checked against what this LibTorch
// build and machine offer, so that a missing GPU is one clear error up front
// rather than a LibTorch exception in the middle of a denoise.
#pragma once

#include <torch/torch.h>

#include <optional>
#include <string>

namespace dn {

// "cpu", "cuda" or "cuda:N". Throws std::invalid_argument naming what is
// missing: an unknown name, a LibTorch built without CUDA or no GPU visible,
// or a CUDA index past the devices present.
torch::Device parseDevice(const std::string& name);

// Throws std::invalid_argument unless tensors can be placed on `device`.
void checkDeviceAvailable(const torch::Device& device);

// Bytes a CUDA device can still give this process: what its driver reports
// free plus what LibTorch's caching allocator holds unused (so that a second
// frame sees the memory the first one left cached). std::nullopt where this
// build cannot ask (configured without the CUDA runtime's headers). Throws
// std::invalid_argument for another device.
std::optional<double> freeDeviceMemory(const torch::Device& device);

// Whether this CPU computes bfloat16 natively (AMX or AVX-512 BF16), where
// oneDNN's bfloat16 convolutions are faster than its float ones.
bool cpuComputesBFloat16();

}  // namespace dn
