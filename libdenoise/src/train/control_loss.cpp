#include "dn/train/control_loss.h"

#include "dn/diffusion/refine.h"
#include "dn/infer/control_inputs.h"
#include "dn/tonemap.h"

namespace dn {

torch::Tensor batchExposure(const torch::Tensor& color) {
  const torch::Tensor hwc =
      color.to(torch::kCPU, torch::kFloat32).permute({0, 2, 3, 1}).contiguous();
  std::vector<float> values;
  for (int64_t b = 0; b < hwc.size(0); ++b) {
    Image image(int(hwc.size(2)), int(hwc.size(1)), 3);
    std::copy_n(hwc[b].data_ptr<float>(), image.pixels.size(), image.pixels.begin());
    values.push_back(tonemap::oidnExposure(image));
  }
  return torch::tensor(values);
}

torch::Tensor controlLoss(OidnControlledImpl& model, const ModelInfo& info, const TrainBatch& batch,
                          torch::Generator& generator) {
  const OidnControlConfig& config = info.oidn.control;
  const OidnInputSet& set = oidnInputSet(config.input_set);
  const int64_t b = batch.noisy.size(0), baseAux = 3 * (int64_t(set.buffers.size()) - 1);
  TORCH_CHECK(batch.aux.defined() && batch.aux.size(1) == baseAux + config.extraChannels(),
              "batch aux must hold the base's buffers and the extras");
  const torch::Tensor exposure = batchExposure(batch.noisy);
  torch::Tensor guides = batch.aux.narrow(1, 0, baseAux);
  if (set.cleanAux) {  // the prefilter mode's network: its guides cleaned first, as dndenoise does
    torch::NoGradGuard noGrad;
    guides = cleanAux(model.base(), guides.narrow(1, 0, 3), guides.narrow(1, 3, 3));
  }
  const torch::Tensor baseInput =
      oidnBaseInput(torch::cat({batch.noisy, guides}, 1), set, exposure);
  const torch::Tensor target = puEncode(batch.target * exposure.view({b, 1, 1, 1}));

  const torch::Tensor keep =
      (torch::rand({b}, generator) >= kExtraDropout).to(torch::kFloat32).view({b, 1});
  const torch::Tensor present =
      (batch.present.defined() ? batch.present
                               : torch::ones({b, int64_t(config.extra_buffers.size())})) *
      keep;
  const torch::Tensor extras =
      batch.aux.narrow(1, baseAux, config.extraChannels()) * keep.view({b, 1, 1, 1});

  OidnUNetImpl::Features features;
  torch::Tensor hint;
  {
    torch::NoGradGuard noGrad;
    features = model.steered()->encode(baseInput);
  }
  if (config.diffusion) {
    const torch::Tensor sigma = drawSigmas(b, kTrainSigmaMin, kTrainSigmaMax, generator);
    torch::Tensor start;
    {
      torch::NoGradGuard noGrad;
      const torch::Tensor fromBase = (torch::rand({b}, generator) < 0.5).view({b, 1, 1, 1});
      start = torch::where(fromBase, model.steered()->decode(features), target);
    }
    const torch::Tensor noise = torch::randn(target.sizes(), generator);
    const torch::Tensor state = start + sigma.view({b, 1, 1, 1}) * noise;
    hint = controlHint(config, extras, present, exposure, state, sigma);
  } else {
    hint = controlHint(config, extras, present, exposure);
  }
  return torch::l1_loss(model.decode(features, baseInput, hint), target);
}

}  // namespace dn
