// Ancestral DDPM and DDIM sampling over a (respaced) schedule, with the paper's
// step skipping: instead of pure noise, start part-way by forward-diffusing the
// conditioning image (the noisy render) to the starting step.
#pragma once

#include <cstdint>
#include <functional>

#include <torch/torch.h>

#include "dn/diffusion/schedule.h"

namespace dn {

enum class SamplerKind { Ddpm, Ddim };

struct SamplerOptions {
  SamplerKind kind = SamplerKind::Ddpm;
  double eta = 0.0;        // DDIM noise: 0 deterministic, 1 matches DDPM's variance
  int64_t skip_steps = 0;  // noisiest steps to skip; 0 starts from pure noise
  uint64_t seed = 0;       // every random draw comes from a generator with this seed
  bool clip_x0 = true;     // clamp predicted x0 to the data range [-1, 1]
  std::function<void(int64_t done, int64_t total)> progress;  // after every step
};

// The model as the sampler sees it: output (of the schedule's prediction type)
// for z_t at the given model timesteps (B).
using DenoiseFn = std::function<torch::Tensor(const torch::Tensor& z_t, const torch::Tensor& t)>;

// q(z_{t-1} | z_t, x0) = N(x0_coef x0 + zt_coef z_t, variance) at step `step`.
struct PosteriorCoefficients {
  double x0_coef;
  double zt_coef;
  double variance;
};
PosteriorCoefficients ddpmPosterior(const NoiseSchedule& schedule, int64_t step);

// The first step executed when skipping `skip_steps` of the schedule's steps.
int64_t startStep(const NoiseSchedule& schedule, int64_t skip_steps);

// The most steps that can be skipped while the forward noise at the start step,
// in image units sqrt((1 - alpha_bar) / alpha_bar), still reaches `noise_std`
// (the render's own noise in model space, times any safety factor). 0 if none.
int64_t maxSkipForNoise(const NoiseSchedule& schedule, double noise_std);

// z at the start step: N(0, I) without skipping, else forward-diffused `start_image`.
torch::Tensor initialLatent(const NoiseSchedule& schedule, const torch::Tensor& start_image,
                            int64_t skip_steps, torch::Generator& generator);

// Runs the reverse process from the start step down to step 0 and returns x0.
// `start_image` (model space) fixes the output shape and is the skipping start.
torch::Tensor sample(const NoiseSchedule& schedule, Prediction prediction, const DenoiseFn& model,
                     const torch::Tensor& start_image, const SamplerOptions& options);

// The data range of the diffusion models is [-1, 1]; tonemapped images are [0, 1].
inline torch::Tensor modelSpaceFromTonemapped(const torch::Tensor& x) { return x * 2.0 - 1.0; }
inline torch::Tensor tonemappedFromModelSpace(const torch::Tensor& x) { return (x + 1.0) * 0.5; }

}  // namespace dn
