#include "dn/train/kernel_trainer.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "dn/nn/model_file.h"
#include "dn/tonemap.h"
#include "dn/train/losses.h"

namespace dn {
namespace {

constexpr const char* kCheckpointKind = "kernel-checkpoint";
constexpr const char* kRunPrefix = "run.";

// The part of a model's metadata a checkpoint must match: everything but notes.
std::string configText(KernelModelInfo info) {
  info.notes.clear();
  return kernelModelInfoToText(info);
}

// Splits checkpoint metadata into the configuration text and the run state.
std::pair<std::string, std::map<std::string, std::string>> splitCheckpointText(
    const std::string& text, const std::string& path) {
  std::string config;
  std::map<std::string, std::string> run_state;
  std::stringstream stream(text);
  for (std::string line; std::getline(stream, line);) {
    if (line.rfind(kRunPrefix, 0) != 0) {
      config += line + "\n";
      continue;
    }
    const auto eq = line.find('=');
    if (eq == std::string::npos) throw ModelError(path + ": damaged run state line");
    const size_t prefix = std::string(kRunPrefix).size();
    run_state[line.substr(prefix, eq - prefix)] = line.substr(eq + 1);
  }
  return {config, run_state};
}

}  // namespace

KernelCheckpointHeader readKernelCheckpointHeader(const std::string& path) {
  auto file = readArchiveFile(path, kCheckpointKind);
  auto [config, run_state] = splitCheckpointText(file.text, path);
  return {kernelModelInfoFromText(config, path), run_state};
}

torch::Tensor kernelNetLoss(const torch::Tensor& prediction, const torch::Tensor& target,
                            double eps) {
  const auto range = [](const torch::Tensor& x) {
    return torch::nan_to_num(x, 0.0, 0.0, 0.0).clamp(0.0, tonemap::kHdrMax);
  };
  return smapeLoss(range(prediction), range(target), eps);
}

KernelTrainer::KernelTrainer(KernelNet net, KernelModelInfo info, KernelTrainerOptions options)
    : net_(std::move(net)), info_(std::move(info)), options_(options) {
  for (auto& parameter : net_->parameters())
    if (parameter.requires_grad()) parameters_.push_back(parameter);
  TORCH_CHECK(!parameters_.empty(), "the kernel net has no trainable parameters");
  for (auto& parameter : parameters_) ema_.push_back(parameter.detach().clone());
  optimizer_ = std::make_unique<torch::optim::Adam>(
      parameters_, torch::optim::AdamOptions(options_.learning_rate));
}

double KernelTrainer::currentLearningRate() const {
  if (options_.halve_every <= 0) return options_.learning_rate;
  return options_.learning_rate * std::pow(0.5, double(step_ / options_.halve_every));
}

double KernelTrainer::step(const torch::Tensor& radiance, const torch::Tensor& aux,
                           const torch::Tensor& target) {
  net_->train();
  for (auto& group : optimizer_->param_groups())
    static_cast<torch::optim::AdamOptions&>(group.options()).lr(currentLearningRate());
  optimizer_->zero_grad();
  auto loss = kernelNetLoss(net_->forward(radiance, aux), target, options_.smape_eps);
  loss.backward();
  if (options_.max_grad_norm > 0)
    torch::nn::utils::clip_grad_norm_(parameters_, options_.max_grad_norm);
  optimizer_->step();
  ++step_;
  updateEma();
  return loss.item<double>();
}

double KernelTrainer::evaluate(const torch::Tensor& radiance, const torch::Tensor& aux,
                               const torch::Tensor& target) {
  torch::NoGradGuard no_grad;
  net_->eval();
  swapEma();
  double loss = 0;
  try {
    loss = kernelNetLoss(net_->forward(radiance, aux), target, options_.smape_eps).item<double>();
  } catch (...) {
    swapEma();
    throw;
  }
  swapEma();
  return loss;
}

void KernelTrainer::updateEma() {
  torch::NoGradGuard no_grad;
  // Warm-up: early averages would otherwise be dominated by the initial weights.
  const double decay = std::min(options_.ema_decay, (1.0 + step_) / (10.0 + step_));
  for (size_t i = 0; i < ema_.size(); ++i) ema_[i].mul_(decay).add_(parameters_[i], 1.0 - decay);
}

void KernelTrainer::swapEma() {
  torch::NoGradGuard no_grad;
  for (size_t i = 0; i < ema_.size(); ++i) {
    auto current = parameters_[i].detach().clone();
    parameters_[i].copy_(ema_[i]);
    ema_[i].copy_(current);
  }
}

void KernelTrainer::saveModel(const std::string& path) {
  swapEma();
  try {
    saveKernelModel(path, info_, net_);
  } catch (...) {
    swapEma();
    throw;
  }
  swapEma();
}

void KernelTrainer::saveCheckpoint(const std::string& path,
                                   const std::map<std::string, std::string>& run_state) {
  std::string text = configText(info_);
  for (const auto& [key, value] : run_state) {
    if (value.find('\n') != std::string::npos || key.find('=') != std::string::npos)
      throw std::invalid_argument("run state '" + key + "' must be one line, no '=' in its key");
    text += kRunPrefix + key + "=" + value + "\n";
  }
  torch::serialize::OutputArchive archive, weights, optimizer, ema;
  net_->save(weights);
  optimizer_->save(optimizer);
  for (size_t i = 0; i < ema_.size(); ++i) ema.write(std::to_string(i), ema_[i]);
  archive.write("weights", weights);
  archive.write("optimizer", optimizer);
  archive.write("ema", ema);
  archive.write("step", torch::tensor(step_, torch::kLong));
  writeArchiveFile(path, kCheckpointKind, text, archive);
}

std::map<std::string, std::string> KernelTrainer::loadCheckpoint(const std::string& path) {
  auto file = readArchiveFile(path, kCheckpointKind);
  auto [config, run_state] = splitCheckpointText(file.text, path);
  if (config != configText(info_))
    throw ModelError(path + ": checkpoint was written for a different network configuration");
  try {
    torch::serialize::InputArchive weights, optimizer, ema;
    file.archive.read("weights", weights);
    loadModuleWeights(*net_, weights, path);
    file.archive.read("optimizer", optimizer);
    optimizer_->load(optimizer);
    file.archive.read("ema", ema);
    for (size_t i = 0; i < ema_.size(); ++i) {
      torch::Tensor value;
      ema.read(std::to_string(i), value);
      if (!value.sizes().equals(ema_[i].sizes()))
        throw ModelError(path + ": EMA weight " + std::to_string(i) + " has the wrong shape");
      ema_[i].copy_(value);
    }
    torch::Tensor step;
    file.archive.read("step", step);
    step_ = step.item<int64_t>();
  } catch (const c10::Error& error) {
    const std::string what = error.what_without_backtrace();
    throw ModelError(path + ": incomplete checkpoint (" + what.substr(0, what.find('\n')) + ")");
  }
  return run_state;
}

}  // namespace dn
