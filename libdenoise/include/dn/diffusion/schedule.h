// Noise schedules of a discrete Gaussian diffusion process, the forward process
// q(z_t | x0), respacing to fewer steps, and conversions between what a model
// predicts (eps, v or x0). Pure functions on doubles and tensors.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <torch/torch.h>

namespace dn {

enum class ScheduleKind { Linear, Cosine };
enum class Prediction { Epsilon, V, X0 };

// One discrete schedule. For a schedule respaced to K steps, step i (0 = least
// noisy) keeps the original alpha_bar of original timestep `timesteps[i]`, and
// the model is called with that original timestep.
struct NoiseSchedule {
  std::vector<double> betas;           // beta_i = 1 - alpha_bar_i / alpha_bar_{i-1}
  std::vector<double> alphas_cumprod;  // alpha_bar_i, decreasing
  std::vector<int64_t> timesteps;      // original timestep of each step

  int64_t size() const { return static_cast<int64_t>(betas.size()); }
  double alphaBar(int64_t step) const { return alphas_cumprod.at(step); }
  // alpha_bar of the step before `step`; 1 before the first step.
  double alphaBarPrev(int64_t step) const { return step == 0 ? 1.0 : alphas_cumprod.at(step - 1); }
};

// Improved-DDPM schedules: linear betas 1e-4..0.02 (scaled to the step count) and
// the cosine alpha_bar with offset s = 0.008 (betas clipped to 0.999).
NoiseSchedule makeSchedule(ScheduleKind kind, int64_t steps = 1000);
NoiseSchedule makeLinearSchedule(int64_t steps, double beta_start, double beta_end);
NoiseSchedule scheduleFromAlphasCumprod(std::vector<double> alphas_cumprod);

// Timesteps chosen by a respacing spec over `num_timesteps`:
//   "super27", "smart27", "fast27", ... (DeepFloyd IF's named section counts),
//   "10,10,7" (section counts: the range is cut into equal sections and each
//   takes that many evenly strided steps), "ddim25" (uniform stride).
// Returns sorted unique timesteps; throws std::invalid_argument on a bad spec.
std::vector<int64_t> respacedTimesteps(int64_t num_timesteps, const std::string& spec);

// Keeps only `timesteps` of `base` and recomputes betas from alphas_cumprod so the
// marginals q(z_t | x0) at the kept steps are unchanged.
NoiseSchedule respace(const NoiseSchedule& base, const std::vector<int64_t>& timesteps);
NoiseSchedule respace(const NoiseSchedule& base, const std::string& spec);

const char* scheduleKindName(ScheduleKind kind);
ScheduleKind scheduleKindFromName(const std::string& name);  // throws std::invalid_argument
const char* predictionName(Prediction prediction);
Prediction predictionFromName(const std::string& name);  // throws std::invalid_argument

// alpha_bar at the given steps (int64 tensor of shape (B)) as float (B,1,1,1).
torch::Tensor alphaBarAt(const NoiseSchedule& schedule, const torch::Tensor& steps);
// The original (model) timesteps of the given steps, as float (B).
torch::Tensor modelTimestepsAt(const NoiseSchedule& schedule, const torch::Tensor& steps);

// Forward process: z_t = sqrt(alpha_bar) x0 + sqrt(1 - alpha_bar) noise.
// `alpha_bar` broadcasts against x0, e.g. (B,1,1,1).
torch::Tensor forwardDiffuse(const torch::Tensor& x0, const torch::Tensor& noise,
                             const torch::Tensor& alpha_bar);

// Conversions between parameterisations at a given alpha_bar (broadcastable):
//   eps: z = a x0 + s eps;  v = a eps - s x0;  with a = sqrt(alpha_bar), s = sqrt(1 - alpha_bar).
torch::Tensor x0FromPrediction(Prediction kind, const torch::Tensor& output,
                               const torch::Tensor& z_t, const torch::Tensor& alpha_bar);
torch::Tensor epsFromPrediction(Prediction kind, const torch::Tensor& output,
                                const torch::Tensor& z_t, const torch::Tensor& alpha_bar);
// The training target of a model of type `kind` for a sample built from (x0, eps).
torch::Tensor predictionTarget(Prediction kind, const torch::Tensor& x0, const torch::Tensor& eps,
                               const torch::Tensor& alpha_bar);

}  // namespace dn
