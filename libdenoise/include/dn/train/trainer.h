// One gradient step at a time for a ConditionalDenoiser (a base prior on its own,
// or a frozen base under a Control Module): epsilon- or v-prediction MSE, AdamW
// with step-wise learning-rate halving, an EMA of the trainable weights, and
// atomic checkpoints that resume exactly. An app feeds it TrainBatch values.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <torch/torch.h>

#include "dn/diffusion/schedule.h"
#include "dn/nn/model_file.h"
#include "dn/nn/prior.h"
#include "dn/train/distributed.h"

namespace dn {

// Diffusion-UNet models: all images tonemapped to [0, 1]. OIDN-based models:
// linear HDR as rendered, aux unnormalized (the loss prepares them as OIDN does).
// Height and width may be anything.
struct TrainBatch {
  torch::Tensor noisy;    // (B,3,H,W) the noisy render: the conditioning image
  torch::Tensor aux;      // (B,C,H,W) auxiliary buffers, or undefined when unused
  torch::Tensor target;   // (B,3,H,W) the clean image
  torch::Tensor present;  // (B, aux buffers) 1 where the render had the buffer (OIDN-based)
};

// Which (z_t, t) pairs the diffusion loss trains on.
struct DiffusionLossOptions {
  int64_t max_timestep = 0;  // timesteps drawn below this one only (0: the whole schedule)
  // Fraction of samples whose z_t forward-diffuses the noisy render instead of the
  // target, as dndenoise starts sampling, at a step whose noise covers the render's
  // RMS noise level; the target is then the effective noise (z_t - a x0) / s.
  double render_start = 0.0;
};

struct TrainerOptions {
  double learning_rate = 2e-4;
  int64_t halve_every = 0;     // halve the learning rate every this many steps (0: never)
  double weight_decay = 0.01;  // AdamW's usual default
  double ema_decay = 0.999;
  double max_grad_norm = 1.0;  // 0 disables clipping
  uint64_t seed = 0;
  DiffusionLossOptions diffusion;
};

struct StepStats {
  int64_t step = 0;  // steps completed, including this one
  double loss = 0.0;
  double learning_rate = 0.0;
};

// The diffusion MSE on one batch: uniform timesteps, fresh noise, target of the
// model's prediction type, all drawn from `generator`.
torch::Tensor diffusionLoss(ConditionalDenoiser& model, const NoiseSchedule& schedule,
                            Prediction prediction, const TrainBatch& batch,
                            torch::Generator& generator, const DiffusionLossOptions& options = {});

// The regression ablation's loss: L1 between regressDirect's output and the target.
torch::Tensor regressionLoss(ConditionalDenoiser& model, const TrainBatch& batch);

class Trainer {
 public:
  // `info` describes `model` (it is written into checkpoints and model files).
  Trainer(std::shared_ptr<ConditionalDenoiser> model, ModelInfo info, TrainerOptions options);
  // The Control Module over the frozen OIDN base (controlLoss).
  Trainer(OidnControlled model, ModelInfo info, TrainerOptions options);

  StepStats step(const TrainBatch& batch);
  // Loss without a gradient step, with noise drawn from `seed` (comparable across calls).
  double evaluate(const TrainBatch& batch, uint64_t seed);

  int64_t stepCount() const { return step_; }
  const std::vector<torch::Tensor>& trainableParameters() const { return trainable_; }
  double currentLearningRate() const;
  const ModelInfo& info() const { return info_; }
  std::shared_ptr<ConditionalDenoiser> model() const { return model_; }  // null: OIDN-based
  OidnControlled controlled() const { return controlled_; }              // null: diffusion UNet

  // Everything needed to continue exactly: weights, optimizer, EMA, step, RNG.
  void saveCheckpoint(const std::string& path);
  // Throws ModelError, also when the checkpoint's ModelInfo (notes included)
  // differs from this trainer's.
  void loadCheckpoint(const std::string& path);
  // A model file with the EMA weights (what inference should use).
  void saveEmaModel(const std::string& path);

  // Data-parallel training: step() then averages gradients over all ranks
  // before clipping (its loss is the mean over ranks), and ranks above 0 draw
  // their own diffusion noise. Call on every rank after loadCheckpoint: rank 0's
  // weights and EMA are copied to all ranks; throws std::runtime_error when the
  // ranks are at different steps (each needs the same checkpoint to resume).
  void setGradientAverager(std::shared_ptr<GradientAverager> averager);

 private:
  Trainer(std::shared_ptr<torch::nn::Module> module, ModelInfo info, TrainerOptions options, int);
  // The loss of info_.objective on one batch.
  torch::Tensor loss(const TrainBatch& batch, torch::Generator& generator);
  void updateEma();
  void swapEma();
  // The generator of this step's timesteps and noise (rank-specific in data-parallel runs).
  torch::Generator& noiseGenerator();

  std::shared_ptr<torch::nn::Module> module_;  // what trains, is saved and averaged
  std::shared_ptr<ConditionalDenoiser> model_;
  OidnControlled controlled_{nullptr};
  ModelInfo info_;
  TrainerOptions options_;
  NoiseSchedule schedule_;
  std::vector<torch::Tensor> trainable_;
  std::vector<torch::Tensor> ema_;
  std::unique_ptr<torch::optim::AdamW> optimizer_;
  torch::Generator generator_;
  torch::Generator rankGenerator_;  // ranks above 0: reseeded from (seed, rank, step)
  std::shared_ptr<GradientAverager> averager_;
  int64_t step_ = 0;
};

}  // namespace dn
