#include "dn/train/losses.h"

namespace dn {

torch::Tensor smapeLoss(const torch::Tensor& prediction, const torch::Tensor& target, double eps) {
  TORCH_CHECK(prediction.sizes() == target.sizes() && prediction.dim() >= 1,
              "smapeLoss: prediction and target must have the same shape");
  return ((prediction - target).abs() / (prediction.abs() + target.abs() + eps)).mean();
}

}  // namespace dn
