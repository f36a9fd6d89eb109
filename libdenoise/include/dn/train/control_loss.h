// The training loss of the Control Module over the frozen OIDN base, in the
// base's output space (PU-encoded, exposed radiance), where OIDN itself trains.
//  - one pass (regression): L1 between the steered output and the target;
//  - diffusion: the same L1 on the x0 estimate from a state noised to a level
//    drawn log-uniformly in [kTrainSigmaMin, kTrainSigmaMax], the state built
//    half the time from the target and half from the base's own estimate, as
//    dndenoise starts sampling from it.
// Each sample's extra buffers are dropped (zeros, flags off) with probability
// kExtraDropout, so one model serves renders with and without them.
#pragma once

#include <torch/torch.h>

#include "dn/nn/model_file.h"
#include "dn/nn/oidn_control.h"
#include "dn/train/trainer.h"

namespace dn {

constexpr double kTrainSigmaMin = 0.005, kTrainSigmaMax = 0.15;
constexpr double kExtraDropout = 0.25;

// batch: linear noisy colour, aux = the base's other buffers then the extras,
// present = flags of the extras; exposure is OIDN's autoexposure of each crop.
torch::Tensor controlLoss(OidnControlledImpl& model, const ModelInfo& info, const TrainBatch& batch,
                          torch::Generator& generator);

// OIDN's autoexposure of each image of a (B,3,H,W) linear batch, (B).
torch::Tensor batchExposure(const torch::Tensor& color);

}  // namespace dn
