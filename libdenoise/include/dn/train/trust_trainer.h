// Fitting the temporal filter's learned trust (dn/temporal/learned_trust.h)
// on what temporal_refilter --dump-trust writes: per frame, every kept
// neighbour's features and result brought in, the frame's own result and an
// independent render of it. The loss is the squared error of the filtered
// result against that render, weighted per pixel as Reinhard's curve weighs
// it (the PSNR the toolkit is judged by); the render's noise is independent
// of everything the weights see, so it adds the same to every candidate's
// loss (Noise2Noise) and no clean reference is needed.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include <torch/torch.h>

#include "dn/temporal/learned_trust.h"

namespace dn {

// Pixels of many frames, each with up to `neighbours` neighbours (missing ones
// have zero features, so zero guide trust and no weight).
struct TrustSet {
  torch::Tensor features;  // (N, K, kTrustFeatureCount)
  torch::Tensor moved;     // (N, K, 3) the neighbours' results brought in
  torch::Tensor own;       // (N, 3) the frame's result
  torch::Tensor target;    // (N, 3) its independent render
  torch::Tensor scale;     // (N) the frame's autoexposure
  torch::Tensor rules;     // (N, K) the weights the dump's filter gave
  int64_t frames = 0;
  int64_t size() const { return own.defined() ? own.size(0) : 0; }
};

// Every frame of the dump folders; of each, the pixels where the rules gave
// some neighbour weight, every `stride`-th of them. Throws dn::npy::NpyError on a bad file.
TrustSet loadTrustSet(const std::vector<std::string>& dumpDirs, int stride = 1);

// The loss of weights (N, K) on `set`: the mean over pixels of the squared
// error of (own + sum w moved) / (1 + sum w) against the target, each pixel's
// weighed by Reinhard's slope at the frame's result, to the fourth power.
double trustLoss(const TrustSet& set, const torch::Tensor& weights);

// The learned trust's weights on `set`, through LearnedTrust::weigh (as the filter runs it).
torch::Tensor learnedWeights(const TrustSet& set, const temporal::LearnedTrust& trust);

struct TrustFitOptions {
  std::vector<int> hidden = {16, 8};
  int steps = 4000;
  int batch = 16384;
  double learningRate = 3e-3;
  uint64_t seed = 1;
};

// Adam on `set`, the features standardised inside the first layer.
temporal::LearnedTrust fitTrust(const TrustSet& set, const TrustFitOptions& options,
                                const std::function<void(int step, double loss)>& progress = {});

}  // namespace dn
