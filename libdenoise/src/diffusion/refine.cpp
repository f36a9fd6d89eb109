#include "dn/diffusion/refine.h"

#include <cmath>
#include <stdexcept>

namespace dn {

void checkSigmas(const std::vector<double>& sigmas) {
  for (size_t i = 0; i < sigmas.size(); ++i) {
    if (!(sigmas[i] > 0.0)) throw std::invalid_argument("diffusion noise levels must be above 0");
    if (i > 0 && !(sigmas[i] < sigmas[i - 1]))
      throw std::invalid_argument("diffusion noise levels must decrease");
  }
}

torch::Tensor refine(const torch::Tensor& start, const torch::Tensor& noise,
                     const std::vector<double>& sigmas, const X0Fn& x0) {
  checkSigmas(sigmas);
  if (sigmas.empty()) return start;
  torch::Tensor state = start + sigmas.front() * noise;
  torch::Tensor estimate;
  for (size_t i = 0; i < sigmas.size(); ++i) {
    estimate = x0(state, sigmas[i]);
    if (i + 1 == sigmas.size()) break;
    // DDIM (eta = 0): keep the implied noise, scaled to the next level.
    state = estimate + (sigmas[i + 1] / sigmas[i]) * (state - estimate);
  }
  return estimate;
}

torch::Tensor drawSigmas(int64_t count, double lo, double hi, torch::Generator& generator) {
  const double a = std::log(lo), b = std::log(hi);
  return torch::exp(a + (b - a) * torch::rand({count}, generator));
}

}  // namespace dn
