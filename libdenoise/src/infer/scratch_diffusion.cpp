#include "dn/infer/scratch_diffusion.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "dn/experiments/highlights.h"
#include "dn/experiments/mean_match.h"
#include "dn/infer/noise_estimate.h"
#include "dn/infer/tiler.h"
#include "dn/nn/model_inputs.h"

namespace dn {

namespace {

double noteOr(const ModelInfo& info, const std::string& key, double fallback) {
  auto it = info.notes.find(key);
  return it == info.notes.end() ? fallback : std::stod(it->second);
}

// Forward noise at a step in image units, sqrt((1 - alpha_bar) / alpha_bar).
double noiseLevel(const NoiseSchedule& schedule, int64_t step) {
  const double ab = schedule.alphaBar(step);
  return std::sqrt((1.0 - ab) / ab);
}

double autoExposure(const ModelInfo& info, const Image& color) {
  const double target = noteOr(info, "exposure_target", 0);
  return target > 0 ? tonemap::exposureForMean(color, target) : 1.0;
}

double exposureFor(const ModelInfo& info, const Image& color, double requested) {
  const double automatic = autoExposure(info, color);
  if (requested <= 0.0) return automatic;
  checkExposure(requested, automatic);
  return requested;
}

// The render's radiance as the network sees it: exposed, clamped, tonemapped, in [-1, 1].
torch::Tensor modelSpaceRadiance(const ModelInfo& info, const Image& color, double exposure) {
  return modelSpaceFromTonemapped(
      tonemapRadiance(imageToTensor(color) * exposure, tonemap::curveFromName(info.tonemap)));
}

}  // namespace

SamplingPlan planSampling(const ModelInfo& info, const NoiseSchedule& schedule,
                          const ScratchSampling& sampling, int fileSpp, double renderNoise) {
  SamplingPlan plan;
  const double defaultSpp = noteOr(info, "default_spp", 0);
  const double noiseReference = noteOr(info, "noise_reference", 0);
  plan.spp = sampling.spp > 0 ? sampling.spp : fileSpp;
  plan.noise = renderNoise;
  if (sampling.spp <= 0 && noiseReference > 0 && renderNoise >= 0)
    plan.noiseScale = std::clamp(renderNoise / noiseReference, kMinNoiseScale, kMaxNoiseScale);
  else if (defaultSpp > 0 && plan.spp > 0)
    plan.noiseScale = std::sqrt(defaultSpp / plan.spp);
  if (sampling.skip >= 0) {
    plan.skip = sampling.skip;
  } else {
    // The model's default start, as a noise level on its own sampling schedule,
    // carried over to the schedule in use and scaled to the input's noise.
    const NoiseSchedule defaults = info.samplingSchedule();
    const double level =
        noiseLevel(defaults, startStep(defaults, int64_t(noteOr(info, "default_skip", 0)))) *
        plan.noiseScale;
    plan.skip = maxSkipForNoise(schedule, level * (1.0 - 1e-9));  // exact default: its own skip
  }
  plan.meanMatchSigma = sampling.meanMatchSigma >= 0 ? sampling.meanMatchSigma
                                                     : kDefaultMeanMatchSigma * plan.noiseScale;
  return plan;
}

double measureModelNoise(const ModelInfo& info, const FrameBuffers& frame, double exposure) {
  torch::NoGradGuard noGrad;
  const Image& color = frame.get("color");
  return estimateNoise(modelSpaceRadiance(info, color, exposureFor(info, color, exposure)), frame);
}

ScratchDiffusionPipeline::ScratchDiffusionPipeline(const ModelInfo& info,
                                                   std::shared_ptr<ConditionalDenoiser> model)
    : info_(info), model_(std::move(model)) {
  model_->eval();
}

std::vector<std::string> ScratchDiffusionPipeline::missingBuffers(
    const std::vector<std::string>& available) const {
  std::vector<std::string> missing;
  for (const auto& name : info_.input_buffers)
    if (std::find(available.begin(), available.end(), name) == available.end())
      missing.push_back(name);
  return missing;
}

std::vector<std::string> ScratchDiffusionPipeline::usableBuffers(
    const std::vector<std::string>&) const {
  std::vector<std::string> usable = {"color"};
  usable.insert(usable.end(), info_.input_buffers.begin(), info_.input_buffers.end());
  return usable;
}

double ScratchDiffusionPipeline::bytesPerPixel() const {
  // Skip features live until the decoder uses them; a few full-width tensors
  // are alive at once in a block; the control copy doubles the encoder.
  const UNetConfig& c = info_.base;
  double skips = 0.0;
  for (int64_t l = 0; l < c.levels(); ++l)
    skips += double(c.base_channels * c.channel_mults[l] * (c.res_blocks + 1)) / std::pow(4.0, l);
  const double encoders = info_.has_control ? 2.0 : 1.0;
  const double working = 8.0 * c.base_channels * c.channel_mults[0];
  const double hint = info_.has_control ? 3.0 * info_.control.hint_channels : 0.0;
  return 4.0 * 1.5 * (encoders * skips + working + hint);
}

DenoiseResult ScratchDiffusionPipeline::denoise(const FrameBuffers& frame,
                                                const DenoiseOptions& options) const {
  if (!options.device.is_cpu())
    throw std::invalid_argument("this diffusion model runs on the CPU only (use --device cpu)");
  torch::NoGradGuard noGrad;
  const ModelInfo& mi = info_;
  const ScratchSampling& sampling = options.scratch;
  const tonemap::Curve curve = tonemap::curveFromName(mi.tonemap);

  // The radiance in model space is full-frame (the sampler starts from it); the
  // aux inputs, ten times as many channels, are normalized per tile on demand.
  const double exposure = exposureFor(mi, frame.get("color"), options.exposure);
  const torch::Tensor cond = modelSpaceRadiance(mi, frame.get("color"), exposure);
  auto auxOf = [&](const TileRect& r) {
    return mi.input_buffers.empty() ? torch::Tensor()
                                    : normalizedAuxRegion(frame, mi.input_buffers, curve, r.y0,
                                                          r.x0, r.height, r.width, exposure);
  };

  const NoiseSchedule schedule = sampling.respacing.empty()
                                     ? mi.samplingSchedule()
                                     : respace(mi.trainingSchedule(), sampling.respacing);
  const bool regression = mi.objective == Objective::Regression;
  // The noise is measured only where the plan uses it, and at the model's own
  // exposure, as its noise_reference was: an exposure changes what the network
  // sees, not how noisy the render is.
  const bool measure = mi.notes.count("noise_reference") && sampling.spp <= 0 &&
                       (sampling.skip < 0 || sampling.meanMatchSigma < 0);
  // At the autoexposure (the default) the network's input is what is measured.
  const double noise = !measure                ? -1.0
                       : options.exposure <= 0 ? estimateNoise(cond, frame)
                                               : measureModelNoise(mi, frame);
  const SamplingPlan plan = planSampling(mi, schedule, sampling, frame.samplesPerPixel, noise);
  const int64_t skip = plan.skip;
  startStep(schedule, skip);  // validates skip against the step count
  const int64_t steps = regression ? 1 : schedule.size() - skip;
  // A regression model is deterministic: more samples would be identical copies.
  const int samples = regression ? 1 : options.samples;

  const int64_t multiple = model_->sizeMultiple();
  // Self-attention cost grows with the square of a tile's pixel count: with tiles
  // sized only by the memory budget, one network step on a 1080p frame ran for
  // over 6 minutes on 2 cores. The model also trained on 64 px crops.
  const int64_t tile =
      options.tile > 0
          ? options.tile
          : std::min<int64_t>(kMaxDefaultTile,
                              tileSizeForMemory(options.maxMemoryBytes, bytesPerPixel(), multiple));
  const Tiler tiler(frame.height, frame.width, tile, options.overlap);
  ConditionalDenoiser& net = *model_;
  DenoiseFn fn = [&](const torch::Tensor& z_t, const torch::Tensor& t) {
    return tiler.apply(
        [&](const TileRect& r) { return net.predict(crop(z_t, r), t, crop(cond, r), auxOf(r)); });
  };
  auto sampleOnce = [&](int k) {
    if (regression) {
      auto x0 = tiler.apply(
          [&](const TileRect& r) { return regressDirect(net, crop(cond, r), auxOf(r)); });
      if (options.progress) options.progress(1.0);
      return x0.clamp(-1.0, 1.0);
    }
    SamplerOptions so;
    so.kind = sampling.sampler;
    so.eta = sampling.eta;
    so.skip_steps = skip;
    so.seed = options.seed + static_cast<uint64_t>(k);
    if (options.progress)
      so.progress = [&, k](int64_t done, int64_t total) {
        options.progress((k + double(done) / total) / samples);
      };
    return sample(schedule, mi.prediction, fn, cond, so);
  };

  torch::Tensor sum, sumSquares;
  for (int k = 0; k < samples; ++k) {
    torch::Tensor hdr =
        inverseTonemapRadiance(tonemappedFromModelSpace(sampleOnce(k)), curve) / exposure;
    if (samples > 1) sumSquares = k == 0 ? hdr * hdr : sumSquares + hdr * hdr;
    sum = k == 0 ? hdr : sum + hdr;  // hdr is a fresh tensor every sample
  }

  DenoiseResult result;
  const double n = samples;
  torch::Tensor mean = sum / n;
  const torch::Tensor render = imageToTensor(frame.get("color"));
  const double rangeMax = tonemap::kHdrMax / exposure;  // the model's range in input units
  // The render's own evidence where the network cannot be trusted: its local
  // means, its lights above the model's range and its black.
  torch::Tensor color = matchLocalMean(mean, render, plan.meanMatchSigma, 4.0, rangeMax);
  color = keepBlack(restoreHighlights(color, render, rangeMax), render, blackWindow(plan.spp));
  result.color = tensorToImage(color);
  if (samples > 1) {
    torch::Tensor variance = (sumSquares / n - mean * mean).clamp_min(0.0) * (n / (n - 1));
    result.uncertainty = tensorToImage(variance.sqrt().mean(1, true));
  }
  result.plan = plan;
  result.exposure = exposure;
  result.steps = steps;
  result.tileSize = std::min<int64_t>(tile, std::max(frame.width, frame.height));
  result.tileCount = tiler.tiles().size();
  result.buffersUsed = usableBuffers(frame.names());
  return result;
}

}  // namespace dn
