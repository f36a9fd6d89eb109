// Training of a KernelNet (cleanser or Isik-style denoiser): SMAPE on linear
// radiance clamped to the model range, Adam with step-wise learning-rate halving,
// an EMA of the weights (what model files get), and checkpoints that carry the
// caller's run state (e.g. the data loader position) so a run resumes exactly.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <torch/torch.h>

#include "dn/nn/kernel_net.h"

namespace dn {

struct KernelTrainerOptions {
  double learning_rate = 1e-3;
  int64_t halve_every = 0;  // halve the learning rate every this many steps (0: never)
  double ema_decay = 0.999;
  double max_grad_norm = 1.0;  // 0 disables clipping
  double smape_eps = 1e-2;
};

// The training loss: SMAPE of prediction and target, both linear HDR radiance
// clamped to [0, 6] (the paper's HDR range), so lights do not dominate.
torch::Tensor kernelNetLoss(const torch::Tensor& prediction, const torch::Tensor& target,
                            double eps);

// What a checkpoint was written for, read without building a network: the
// configuration (notes empty) and the run state. Throws dn::ModelError.
struct KernelCheckpointHeader {
  KernelModelInfo info;
  std::map<std::string, std::string> run_state;
};
KernelCheckpointHeader readKernelCheckpointHeader(const std::string& path);

class KernelTrainer {
 public:
  KernelTrainer(KernelNet net, KernelModelInfo info, KernelTrainerOptions options);

  // One Adam step on a batch: radiance and target linear (B,3,H,W), aux raw (B,C,H,W).
  // Returns the loss before the step.
  double step(const torch::Tensor& radiance, const torch::Tensor& aux, const torch::Tensor& target);
  // Loss of the EMA weights (the ones saved to model files), without a step.
  double evaluate(const torch::Tensor& radiance, const torch::Tensor& aux,
                  const torch::Tensor& target);

  int64_t stepCount() const { return step_; }
  double currentLearningRate() const;
  KernelModelInfo& info() { return info_; }
  KernelNet net() const { return net_; }

  // Everything needed to continue exactly: weights, optimizer, EMA, step, plus
  // `run_state` (one-line values) that loadCheckpoint hands back.
  void saveCheckpoint(const std::string& path, const std::map<std::string, std::string>& run_state);
  // Throws dn::ModelError if the file is damaged or holds another network configuration.
  std::map<std::string, std::string> loadCheckpoint(const std::string& path);
  // A model file with the EMA weights.
  void saveModel(const std::string& path);

 private:
  void updateEma();
  void swapEma();

  KernelNet net_;
  KernelModelInfo info_;
  KernelTrainerOptions options_;
  std::vector<torch::Tensor> parameters_, ema_;
  std::unique_ptr<torch::optim::Adam> optimizer_;
  int64_t step_ = 0;
};

}  // namespace dn
