// Training losses shared by the trainers.
#pragma once

#include <torch/torch.h>

namespace dn {

// SMAPE(A, B) = |A - B|_1 / (|A|_1 + |B|_1 + eps) per sample (the paper's Eq. 2),
// averaged over the batch (dim 0). |.|_1 is the mean absolute value over a
// sample's elements, so eps means the same at every image size. The loss is
// relative: a dark image weighs as much as a bright one.
torch::Tensor smapeLoss(const torch::Tensor& prediction, const torch::Tensor& target,
                        double eps = 1e-2);

}  // namespace dn
