// Diffusion refinement over the base's estimate, the paper's step skipping from
// a far better start: the state is the image plus Gaussian noise of level sigma
// (the variance-exploding form of DDPM: z_t / sqrt(alpha_bar_t) = x0 + sigma_t
// eps, sigma_t = sqrt((1 - alpha_bar_t) / alpha_bar_t)). Sampling starts from
// the base's estimate noised to the first level and takes deterministic DDIM
// steps (eta = 0) down the given levels; each step asks the model for x0.
#pragma once

#include <cstdint>
#include <functional>
#include <vector>

#include <torch/torch.h>

namespace dn {

// The model's x0 estimate from a state and its noise level.
using X0Fn = std::function<torch::Tensor(const torch::Tensor& state, double sigma)>;

// Noise levels of a refinement, first (noisiest) to last, all > 0, decreasing;
// throws std::invalid_argument otherwise.
void checkSigmas(const std::vector<double>& sigmas);

// `noise`: a standard normal tensor shaped like `start` (drawn by the caller,
// so that tiles of one frame share it). Returns the last x0 estimate; with no
// levels, `start` itself.
torch::Tensor refine(const torch::Tensor& start, const torch::Tensor& noise,
                     const std::vector<double>& sigmas, const X0Fn& x0);

// Training levels: log-uniform in [lo, hi], one per batch item.
torch::Tensor drawSigmas(int64_t count, double lo, double hi, torch::Generator& generator);

}  // namespace dn
