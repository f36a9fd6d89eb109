#include "dn/train/trainer.h"

#include <ATen/CPUGeneratorImpl.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "dn/diffusion/sampler.h"
#include "dn/train/control_loss.h"

namespace dn {
namespace {

// SplitMix64: well-mixed seeds from structured inputs (rank, step).
uint64_t mixSeed(uint64_t value) {
  value += 0x9E3779B97F4A7C15ull;
  value = (value ^ (value >> 30)) * 0xBF58476D1CE4E5B9ull;
  value = (value ^ (value >> 27)) * 0x94D049BB133111EBull;
  return value ^ (value >> 31);
}

void checkBatch(const TrainBatch& batch) {
  TORCH_CHECK(batch.noisy.defined() && batch.target.defined(), "batch needs noisy and target");
  TORCH_CHECK(batch.noisy.dim() == 4 && batch.noisy.sizes() == batch.target.sizes(),
              "noisy and target must both be (B,3,H,W) of the same size");
  if (batch.aux.defined())
    TORCH_CHECK(batch.aux.dim() == 4 && batch.aux.size(0) == batch.noisy.size(0) &&
                    batch.aux.size(2) == batch.noisy.size(2) &&
                    batch.aux.size(3) == batch.noisy.size(3),
                "aux must be (B,C,H,W) matching the noisy image");
}

// A step between the first whose forward noise covers the render's noise (RMS:
// a median is 0 on black backgrounds), where sampling would start, and maxStep.
int64_t renderStartStep(const NoiseSchedule& schedule, const torch::Tensor& renderNoise,
                        int64_t maxStep, torch::Generator& generator) {
  const double level = renderNoise.pow(2).mean().sqrt().item<double>();
  const int64_t cover = schedule.size() - 1 - maxSkipForNoise(schedule, level);
  const int64_t span = std::max<int64_t>(1, maxStep - cover);
  return std::min(cover + torch::randint(0, span, {1}, generator).item<int64_t>(),
                  schedule.size() - 1);
}

}  // namespace

torch::Tensor diffusionLoss(ConditionalDenoiser& model, const NoiseSchedule& schedule,
                            Prediction prediction, const TrainBatch& batch,
                            torch::Generator& generator, const DiffusionLossOptions& options) {
  checkBatch(batch);
  const auto x0 = modelSpaceFromTonemapped(batch.target);
  const auto cond = modelSpaceFromTonemapped(batch.noisy);
  const int64_t b = x0.size(0);
  const int64_t maxStep = options.max_timestep > 0
                              ? std::clamp<int64_t>(options.max_timestep, 1, schedule.size())
                              : schedule.size();
  auto steps = torch::randint(0, maxStep, {b}, generator, torch::kLong);
  auto noise = torch::randn(x0.sizes(), generator, x0.options());
  if (options.render_start <= 0) {
    auto alpha_bar = alphaBarAt(schedule, steps);
    auto output = model.predict(forwardDiffuse(x0, noise, alpha_bar),
                                modelTimestepsAt(schedule, steps), cond, batch.aux);
    return torch::mse_loss(output, predictionTarget(prediction, x0, noise, alpha_bar));
  }
  auto fromRender = torch::rand({b}, generator) < options.render_start;
  auto start = x0.clone();
  for (int64_t i = 0; i < b; ++i) {
    if (!fromRender[i].item<bool>()) continue;
    start[i] = cond[i];
    steps[i] = renderStartStep(schedule, cond[i] - x0[i], maxStep, generator);
  }
  auto alpha_bar = alphaBarAt(schedule, steps);
  auto z_t = forwardDiffuse(start, noise, alpha_bar);
  // The noise z_t carries relative to the target: the injected noise plus the
  // render's own, so starting from a noised render is what the model learns.
  auto eps = torch::where(fromRender.view({b, 1, 1, 1}),
                          (z_t - alpha_bar.sqrt() * x0) / (1 - alpha_bar).sqrt(), noise);
  auto output = model.predict(z_t, modelTimestepsAt(schedule, steps), cond, batch.aux);
  return torch::mse_loss(output, predictionTarget(prediction, x0, eps, alpha_bar));
}

torch::Tensor regressionLoss(ConditionalDenoiser& model, const TrainBatch& batch) {
  checkBatch(batch);
  const auto x0 = modelSpaceFromTonemapped(batch.target);
  const auto output = regressDirect(model, modelSpaceFromTonemapped(batch.noisy), batch.aux);
  return torch::l1_loss(output, x0);
}

Trainer::Trainer(std::shared_ptr<ConditionalDenoiser> model, ModelInfo info, TrainerOptions options)
    : Trainer(model, std::move(info), options, 0) {
  model_ = std::move(model);
}

Trainer::Trainer(OidnControlled model, ModelInfo info, TrainerOptions options)
    : Trainer(model.ptr(), std::move(info), options, 0) {
  controlled_ = std::move(model);
}

Trainer::Trainer(std::shared_ptr<torch::nn::Module> module, ModelInfo info, TrainerOptions options,
                 int)
    : module_(std::move(module)),
      info_(std::move(info)),
      options_(options),
      schedule_(info_.trainingSchedule()),
      generator_(at::detail::createCPUGenerator(options.seed)) {
  for (auto& parameter : module_->parameters())
    if (parameter.requires_grad()) trainable_.push_back(parameter);
  TORCH_CHECK(!trainable_.empty(), "the model has no trainable parameters");
  for (auto& parameter : trainable_) ema_.push_back(parameter.detach().clone());
  optimizer_ = std::make_unique<torch::optim::AdamW>(
      trainable_,
      torch::optim::AdamWOptions(options_.learning_rate).weight_decay(options_.weight_decay));
}

double Trainer::currentLearningRate() const {
  if (options_.halve_every <= 0) return options_.learning_rate;
  return options_.learning_rate * std::pow(0.5, double(step_ / options_.halve_every));
}

StepStats Trainer::step(const TrainBatch& batch) {
  module_->train();
  const double lr = currentLearningRate();
  for (auto& group : optimizer_->param_groups())
    static_cast<torch::optim::AdamWOptions&>(group.options()).lr(lr);
  optimizer_->zero_grad();
  auto value = loss(batch, noiseGenerator());
  value.backward();
  if (averager_) averager_->averageGradients(trainable_);
  if (options_.max_grad_norm > 0)
    torch::nn::utils::clip_grad_norm_(trainable_, options_.max_grad_norm);
  optimizer_->step();
  ++step_;
  updateEma();
  const double meanLoss =
      averager_ ? averager_->average(value.item<double>()) : value.item<double>();
  return {step_, meanLoss, lr};
}

torch::Generator& Trainer::noiseGenerator() {
  if (!averager_ || averager_->isMain()) return generator_;
  // Rank 0 keeps the checkpointed generator; the others derive theirs from the
  // step, so a resumed run draws the same noise without per-rank checkpoints.
  const uint64_t rank = static_cast<uint64_t>(averager_->rank());
  rankGenerator_ = at::detail::createCPUGenerator(
      mixSeed(mixSeed(mixSeed(options_.seed) ^ rank) ^ static_cast<uint64_t>(step_)));
  return rankGenerator_;
}

void Trainer::setGradientAverager(std::shared_ptr<GradientAverager> averager) {
  averager_ = std::move(averager);
  if (!averager_) return;
  auto mainStep = torch::tensor({step_}, torch::kLong);
  averager_->broadcastParameters({mainStep});
  const bool differs = mainStep.item<int64_t>() != step_;
  if (averager_->any(differs))  // every rank stops, not only the odd one
    throw std::runtime_error(
        "rank " + std::to_string(averager_->rank()) + " is at step " + std::to_string(step_) +
        (differs ? " but rank 0 at step " + std::to_string(mainStep.item<int64_t>())
                 : ", another rank is not") +
        " (resume needs the same checkpoint on every rank)");
  // Frozen weights included, so every rank runs the same network.
  averager_->broadcastParameters(module_->parameters());
  averager_->broadcastParameters(ema_);
}

double Trainer::evaluate(const TrainBatch& batch, uint64_t seed) {
  torch::NoGradGuard no_grad;
  module_->eval();
  auto generator = at::detail::createCPUGenerator(seed);
  return loss(batch, generator).item<double>();
}

torch::Tensor Trainer::loss(const TrainBatch& batch, torch::Generator& generator) {
  if (controlled_) return controlLoss(*controlled_, info_, batch, generator);
  if (info_.objective == Objective::Regression) return regressionLoss(*model_, batch);
  return diffusionLoss(*model_, schedule_, info_.prediction, batch, generator, options_.diffusion);
}

void Trainer::updateEma() {
  torch::NoGradGuard no_grad;
  // Warm-up: early averages would otherwise be dominated by the initial weights.
  const double decay = std::min(options_.ema_decay, (1.0 + step_) / (10.0 + step_));
  for (size_t i = 0; i < ema_.size(); ++i) ema_[i].mul_(decay).add_(trainable_[i], 1.0 - decay);
}

void Trainer::swapEma() {
  torch::NoGradGuard no_grad;
  for (size_t i = 0; i < ema_.size(); ++i) {
    auto current = trainable_[i].detach().clone();
    trainable_[i].copy_(ema_[i]);
    ema_[i].copy_(current);
  }
}

void Trainer::saveEmaModel(const std::string& path) {
  swapEma();
  try {
    saveModelFile(path, info_, *module_);
  } catch (...) {
    swapEma();
    throw;
  }
  swapEma();
}

void Trainer::saveCheckpoint(const std::string& path) {
  torch::serialize::OutputArchive archive, model_archive, optimizer_archive, ema_archive;
  module_->save(model_archive);
  optimizer_->save(optimizer_archive);
  for (size_t i = 0; i < ema_.size(); ++i) ema_archive.write(std::to_string(i), ema_[i]);
  archive.write("model", model_archive);
  archive.write("optimizer", optimizer_archive);
  archive.write("ema", ema_archive);
  archive.write("step", torch::tensor(step_, torch::kLong));
  archive.write("rng", generator_.get_state());
  writeArchiveFile(path, "checkpoint", modelInfoToText(info_), archive);
}

void Trainer::loadCheckpoint(const std::string& path) {
  auto file = readArchiveFile(path, "checkpoint");
  // Notes included: apps record fixed training settings there (batch, crop, seed).
  if (file.text != modelInfoToText(info_))
    throw ModelError(path + ": checkpoint was written for a different model configuration");
  try {
    torch::serialize::InputArchive model_archive, optimizer_archive, ema_archive;
    file.archive.read("model", model_archive);
    loadModuleWeights(*module_, model_archive, path);
    file.archive.read("optimizer", optimizer_archive);
    optimizer_->load(optimizer_archive);
    file.archive.read("ema", ema_archive);
    for (size_t i = 0; i < ema_.size(); ++i) {
      torch::Tensor value;
      ema_archive.read(std::to_string(i), value);
      if (!value.sizes().equals(ema_[i].sizes()))
        throw ModelError(path + ": EMA weight " + std::to_string(i) + " has the wrong shape");
      ema_[i].copy_(value);
    }
    torch::Tensor step, rng;
    file.archive.read("step", step);
    file.archive.read("rng", rng);
    step_ = step.item<int64_t>();
    generator_.set_state(rng);
  } catch (const c10::Error& error) {
    const std::string what = error.what_without_backtrace();
    throw ModelError(path + ": incomplete checkpoint (" + what.substr(0, what.find('\n')) + ")");
  }
}

}  // namespace dn
