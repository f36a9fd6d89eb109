#include "dn/nn/prior.h"

#include "dn/nn/nn_blocks.h"

namespace dn {

torch::Tensor ConditionalDenoiser::predict(const torch::Tensor& z_t, const torch::Tensor& t,
                                           const torch::Tensor& cond, const torch::Tensor& aux) {
  const int64_t height = z_t.size(-2), width = z_t.size(-1);
  const int64_t multiple = sizeMultiple();
  auto padded_aux = aux.defined() ? nn::padToMultiple(aux, multiple) : aux;
  auto out =
      forward(nn::padToMultiple(z_t, multiple), t, nn::padToMultiple(cond, multiple), padded_aux);
  return nn::cropTo(out, height, width);
}

PriorDenoiser::PriorDenoiser(std::shared_ptr<DenoisingPrior> prior) : prior_(std::move(prior)) {
  register_module("prior", prior_);
}

torch::Tensor PriorDenoiser::forward(const torch::Tensor& z_t, const torch::Tensor& t,
                                     const torch::Tensor& cond, const torch::Tensor&) {
  return prior_->predict(z_t, t, cond, nullptr);
}

torch::Tensor regressDirect(ConditionalDenoiser& model, const torch::Tensor& cond,
                            const torch::Tensor& aux) {
  return model.predict(cond, torch::zeros({cond.size(0)}), cond, aux);
}

torch::Tensor denoiseTonemapped(ConditionalDenoiser& model, const NoiseSchedule& schedule,
                                Prediction prediction, const torch::Tensor& radiance,
                                const torch::Tensor& aux, const SamplerOptions& options) {
  model.eval();
  const auto cond = modelSpaceFromTonemapped(radiance);
  DenoiseFn fn = [&](const torch::Tensor& z_t, const torch::Tensor& t) {
    return model.predict(z_t, t, cond, aux);
  };
  auto x0 = sample(schedule, prediction, fn, cond, options);
  return tonemappedFromModelSpace(x0).clamp(0.0, 1.0);
}

}  // namespace dn
