#include "dn/train/trust_trainer.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <stdexcept>

#include "dn/io/npy.h"

namespace dn {

namespace {

using temporal::kGuideTrust;
using temporal::kTrustFeatureCount;
constexpr int64_t kMaxNeighbours = 8;  // the filter's radius of 4, both sides

// The frames of a dump folder: the prefixes of its NNNN.scale.npy files, in order.
std::vector<std::string> dumpedFrames(const std::string& dir) {
  std::vector<std::string> out;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    const std::string name = entry.path().string();
    const std::string suffix = ".scale.npy";
    if (name.size() > suffix.size() &&
        name.compare(name.size() - suffix.size(), suffix.size(), suffix) == 0)
      out.push_back(name.substr(0, name.size() - suffix.size()));
  }
  std::sort(out.begin(), out.end());
  return out;
}

struct Columns {
  std::vector<float> features, moved, own, target, scale, rules;
};

void appendFrame(const std::string& prefix, int stride, Columns& out) {
  const npy::Array own = npy::read(prefix + ".own.npy"), target = npy::read(prefix + ".target.npy");
  const npy::Array moved = npy::read(prefix + ".moved.npy");
  const npy::Array features = npy::read(prefix + ".features.npy");
  const npy::Array weights = npy::read(prefix + ".weights.npy");
  const float scale = npy::read(prefix + ".scale.npy").values.at(0);
  const int64_t k = features.shape.at(0), n = own.shape.at(0) * own.shape.at(1);
  if (k > kMaxNeighbours || features.shape.at(3) != kTrustFeatureCount ||
      target.values.size() != own.values.size())
    throw npy::NpyError(prefix +
                        ".*.npy: not a dump of this version (temporal_refilter --dump-trust)");
  int64_t trusted = 0;
  for (int64_t i = 0; i < n; ++i) {
    bool any = false, finite = true;
    for (int64_t j = 0; j < k; ++j) {
      const float* f = &features.values[(j * n + i) * kTrustFeatureCount];
      any = any || weights.values[j * n + i] > 0.0f;  // the network scales the rules' weight
      for (int c = 0; c < kTrustFeatureCount; ++c) finite = finite && std::isfinite(f[c]);
      for (int c = 0; c < 3; ++c)
        finite = finite && std::isfinite(moved.values[(j * n + i) * 3 + c]);
    }
    for (int c = 0; c < 3; ++c)
      finite =
          finite && std::isfinite(own.values[i * 3 + c]) && std::isfinite(target.values[i * 3 + c]);
    // A pixel of a render's infinite firefly teaches nothing.
    if (!any || !finite || trusted++ % stride != 0) continue;
    for (int64_t j = 0; j < kMaxNeighbours; ++j) {
      const bool present = j < k;
      for (int f = 0; f < kTrustFeatureCount; ++f)
        out.features.push_back(present ? features.values[(j * n + i) * kTrustFeatureCount + f]
                                       : 0.0f);
      for (int c = 0; c < 3; ++c)
        out.moved.push_back(present ? moved.values[(j * n + i) * 3 + c] : 0.0f);
      out.rules.push_back(present ? weights.values[j * n + i] : 0.0f);
    }
    for (int c = 0; c < 3; ++c) {
      out.own.push_back(own.values[i * 3 + c]);
      out.target.push_back(target.values[i * 3 + c]);
    }
    out.scale.push_back(scale);
  }
}

torch::Tensor tensorOf(std::vector<float>& values, std::vector<int64_t> shape) {
  return torch::from_blob(values.data(), shape, torch::kFloat32).clone();
}

// The filtered result's weighted squared error per pixel (N).
torch::Tensor pixelLoss(const torch::Tensor& weights, const torch::Tensor& moved,
                        const torch::Tensor& own, const torch::Tensor& target,
                        const torch::Tensor& scale) {
  const torch::Tensor w = weights.unsqueeze(2);
  const torch::Tensor result = (own + (w * moved).sum(1)) / (1 + w.sum(1));
  const torch::Tensor s = scale.unsqueeze(1);
  const torch::Tensor slope = (1 + (own * s).clamp_min(0)).pow(-4);
  return (((result - target) * s).pow(2) * slope).mean(1);
}

struct Mlp : torch::nn::Module {
  std::vector<torch::nn::Linear> layers;
  torch::Tensor mean, deviation;
  Mlp(const std::vector<int>& sizes, torch::Tensor mean_, torch::Tensor deviation_)
      : mean(std::move(mean_)), deviation(std::move(deviation_)) {
    for (std::size_t l = 1; l < sizes.size(); ++l)
      layers.push_back(
          register_module("layer" + std::to_string(l), torch::nn::Linear(sizes[l - 1], sizes[l])));
  }
  // The weights (..., K) of features (..., K, F) over the rules' (..., K).
  torch::Tensor forward(const torch::Tensor& features, const torch::Tensor& rules) {
    torch::Tensor x = (features - mean) / deviation;
    for (std::size_t l = 0; l < layers.size(); ++l) {
      x = layers[l]->forward(x);
      if (l + 1 < layers.size()) x = torch::relu(x);
    }
    return torch::sigmoid(x.squeeze(-1)) * rules;
  }
  // As LearnedTrust: the standardisation folded into the first layer.
  temporal::LearnedTrust exported(const std::vector<int>& sizes) const {
    torch::NoGradGuard noGrad;
    std::vector<float> params;
    for (std::size_t l = 0; l < layers.size(); ++l) {
      torch::Tensor weight = layers[l]->weight, bias = layers[l]->bias;
      if (l == 0) {
        weight = weight / deviation;
        bias = bias - (weight * mean).sum(1);
      }
      weight = weight.contiguous(), bias = bias.contiguous();
      params.insert(params.end(), weight.data_ptr<float>(),
                    weight.data_ptr<float>() + weight.numel());
      params.insert(params.end(), bias.data_ptr<float>(), bias.data_ptr<float>() + bias.numel());
    }
    return temporal::LearnedTrust(sizes, params);
  }
};

}  // namespace

TrustSet loadTrustSet(const std::vector<std::string>& dumpDirs, int stride) {
  Columns columns;
  TrustSet set;
  for (const std::string& dir : dumpDirs)
    for (const std::string& prefix : dumpedFrames(dir)) {
      appendFrame(prefix, std::max(1, stride), columns);
      ++set.frames;
    }
  const int64_t n = static_cast<int64_t>(columns.scale.size());
  set.features = tensorOf(columns.features, {n, kMaxNeighbours, kTrustFeatureCount});
  set.moved = tensorOf(columns.moved, {n, kMaxNeighbours, 3});
  set.own = tensorOf(columns.own, {n, 3});
  set.target = tensorOf(columns.target, {n, 3});
  set.scale = tensorOf(columns.scale, {n});
  set.rules = tensorOf(columns.rules, {n, kMaxNeighbours});
  return set;
}

double trustLoss(const TrustSet& set, const torch::Tensor& weights) {
  if (set.size() == 0) return 0.0;
  torch::NoGradGuard noGrad;
  return pixelLoss(weights, set.moved, set.own, set.target, set.scale).mean().item<double>();
}

torch::Tensor learnedWeights(const TrustSet& set, const temporal::LearnedTrust& trust) {
  const torch::Tensor features = set.features.contiguous(), rules = set.rules.contiguous();
  torch::Tensor out = torch::zeros({set.size(), kMaxNeighbours});
  const float* f = features.data_ptr<float>();
  const float* r = rules.data_ptr<float>();
  float* w = out.data_ptr<float>();
  for (int64_t i = 0; i < out.numel(); ++i) {
    const float* row = f + i * kTrustFeatureCount;
    if (r[i] > 0.0f) w[i] = r[i] * trust.weigh(row);
  }
  return out;
}

temporal::LearnedTrust fitTrust(const TrustSet& set, const TrustFitOptions& options,
                                const std::function<void(int, double)>& progress) {
  if (set.size() == 0) throw std::invalid_argument("fitTrust: no trusted pixels to fit on");
  torch::manual_seed(options.seed);
  std::vector<int> sizes = {kTrustFeatureCount};
  sizes.insert(sizes.end(), options.hidden.begin(), options.hidden.end());
  sizes.push_back(1);
  // Standardised over the neighbours the guides trust.
  const torch::Tensor rows = set.features.reshape({-1, kTrustFeatureCount});
  const torch::Tensor used = rows.index({rows.select(1, kGuideTrust) > 0});
  const torch::Tensor mean = used.mean(0), deviation = used.std(0).clamp_min(1e-3);
  auto mlp = std::make_shared<Mlp>(sizes, mean, deviation);
  torch::optim::Adam adam(mlp->parameters(), torch::optim::AdamOptions(options.learningRate));
  for (int step = 1; step <= options.steps; ++step) {
    if (step == options.steps * 3 / 4)
      for (auto& group : adam.param_groups())
        static_cast<torch::optim::AdamOptions&>(group.options()).lr(options.learningRate / 10);
    const torch::Tensor pick = torch::randint(set.size(), {options.batch}, torch::kLong);
    const torch::Tensor loss =
        pixelLoss(mlp->forward(set.features.index_select(0, pick), set.rules.index_select(0, pick)),
                  set.moved.index_select(0, pick), set.own.index_select(0, pick),
                  set.target.index_select(0, pick), set.scale.index_select(0, pick))
            .mean();
    adam.zero_grad();
    loss.backward();
    adam.step();
    if (progress) progress(step, loss.item<double>());
  }
  return mlp->exported(sizes);
}

}  // namespace dn
