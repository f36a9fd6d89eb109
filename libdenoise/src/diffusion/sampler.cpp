#include "dn/diffusion/sampler.h"

#include <ATen/CPUGeneratorImpl.h>

#include <cmath>
#include <stdexcept>

namespace dn {
namespace {

torch::Tensor stepTensor(int64_t step, int64_t batch) {
  return torch::full({batch}, step, torch::kLong);
}

torch::Tensor predictX0(const NoiseSchedule& schedule, Prediction prediction,
                        const DenoiseFn& model, const torch::Tensor& z, int64_t step, bool clip) {
  const auto steps = stepTensor(step, z.size(0));
  auto output = model(z, modelTimestepsAt(schedule, steps));
  auto x0 = x0FromPrediction(prediction, output, z, alphaBarAt(schedule, steps));
  return clip ? x0.clamp(-1.0, 1.0) : x0;
}

torch::Tensor ddpmStep(const NoiseSchedule& schedule, const torch::Tensor& z,
                       const torch::Tensor& x0, int64_t step, torch::Generator& generator) {
  const auto posterior = ddpmPosterior(schedule, step);
  auto mean = posterior.x0_coef * x0 + posterior.zt_coef * z;
  if (step == 0) return mean;
  return mean + std::sqrt(posterior.variance) * torch::randn(z.sizes(), generator, z.options());
}

torch::Tensor ddimStep(const NoiseSchedule& schedule, const torch::Tensor& z,
                       const torch::Tensor& x0, int64_t step, double eta,
                       torch::Generator& generator) {
  const double ab = schedule.alphaBar(step);
  const double ab_prev = schedule.alphaBarPrev(step);
  // eps consistent with the (possibly clipped) x0.
  auto eps = (z - std::sqrt(ab) * x0) / std::sqrt(1.0 - ab);
  const double sigma =
      eta * std::sqrt((1.0 - ab_prev) / (1.0 - ab)) * std::sqrt(1.0 - ab / ab_prev);
  auto next =
      std::sqrt(ab_prev) * x0 + std::sqrt(std::max(0.0, 1.0 - ab_prev - sigma * sigma)) * eps;
  if (step == 0 || sigma == 0.0) return next;
  return next + sigma * torch::randn(z.sizes(), generator, z.options());
}

}  // namespace

PosteriorCoefficients ddpmPosterior(const NoiseSchedule& schedule, int64_t step) {
  const double ab = schedule.alphaBar(step);
  const double ab_prev = schedule.alphaBarPrev(step);
  const double beta = schedule.betas.at(step);
  PosteriorCoefficients c;
  c.x0_coef = beta * std::sqrt(ab_prev) / (1.0 - ab);
  c.zt_coef = (1.0 - ab_prev) * std::sqrt(1.0 - beta) / (1.0 - ab);
  c.variance = beta * (1.0 - ab_prev) / (1.0 - ab);
  return c;
}

int64_t startStep(const NoiseSchedule& schedule, int64_t skip_steps) {
  if (skip_steps < 0 || skip_steps >= schedule.size())
    throw std::invalid_argument("skip_steps must be in [0, " + std::to_string(schedule.size() - 1) +
                                "], got " + std::to_string(skip_steps));
  return schedule.size() - 1 - skip_steps;
}

int64_t maxSkipForNoise(const NoiseSchedule& schedule, double noise_std) {
  // Noise decreases with the step index, so scan from the least noisy step up.
  for (int64_t step = 0; step < schedule.size(); ++step) {
    const double ab = schedule.alphaBar(step);
    if (std::sqrt((1.0 - ab) / ab) >= noise_std) return schedule.size() - 1 - step;
  }
  return 0;
}

torch::Tensor initialLatent(const NoiseSchedule& schedule, const torch::Tensor& start_image,
                            int64_t skip_steps, torch::Generator& generator) {
  const int64_t step = startStep(schedule, skip_steps);
  auto noise = torch::randn(start_image.sizes(), generator, start_image.options());
  if (skip_steps == 0) return noise;
  auto alpha_bar = torch::full({1, 1, 1, 1}, schedule.alphaBar(step), start_image.options());
  return forwardDiffuse(start_image, noise, alpha_bar);
}

torch::Tensor sample(const NoiseSchedule& schedule, Prediction prediction, const DenoiseFn& model,
                     const torch::Tensor& start_image, const SamplerOptions& options) {
  torch::NoGradGuard no_grad;
  auto generator = at::detail::createCPUGenerator(options.seed);
  const int64_t first = startStep(schedule, options.skip_steps);
  auto z = initialLatent(schedule, start_image, options.skip_steps, generator);
  const int64_t total = first + 1;
  for (int64_t step = first; step >= 0; --step) {
    auto x0 = predictX0(schedule, prediction, model, z, step, options.clip_x0);
    z = options.kind == SamplerKind::Ddpm ? ddpmStep(schedule, z, x0, step, generator)
                                          : ddimStep(schedule, z, x0, step, options.eta, generator);
    if (options.progress) options.progress(first - step + 1, total);
  }
  return z;
}

}  // namespace dn
