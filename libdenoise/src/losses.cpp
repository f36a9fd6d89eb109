#include "dn/losses.h"

namespace dn {

torch::Tensor smapeLoss(const torch::Tensor& prediction, const torch::Tensor& target, double eps) {
  TORCH_CHECK(prediction.sizes() == target.sizes() && prediction.dim() >= 1,
              "smapeLoss: prediction and target must have the same shape");
  const auto a = prediction.flatten(1), b = target.flatten(1);
  const auto difference = (a - b).abs().mean(1);
  const auto scale = a.abs().mean(1) + b.abs().mean(1) + eps;
  return (difference / scale).mean();
}

}  // namespace dn
