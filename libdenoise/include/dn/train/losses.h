// Training losses shared by the trainers.
#pragma once

#include <torch/torch.h>

namespace dn {

// SMAPE(A, B) = mean over elements of |a - b| / (|a| + |b| + eps): the symmetric
// mean absolute percentage error of Vogels et al. 2018 and Isik et al. 2021, whose
// network and loss the paper's cleanser adopts (its Eq. 2 writes the same with
// norms). Per element, so a dark region weighs as much as a bright one: Monte
// Carlo noise is largest relative to the signal in dark, indirectly lit regions.
torch::Tensor smapeLoss(const torch::Tensor& prediction, const torch::Tensor& target,
                        double eps = 1e-2);

}  // namespace dn
