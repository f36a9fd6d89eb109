#include "dn/denoiser.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "dn/mean_match.h"
#include "dn/model_inputs.h"
#include "dn/tiler.h"

namespace dn {

namespace {

int64_t defaultSkip(const ModelInfo& info) {
  auto it = info.notes.find("default_skip");
  return it == info.notes.end() ? 0 : std::stoll(it->second);
}

}  // namespace

torch::Tensor imageToTensor(const Image& image) {
  return imageRegionToTensor(image, 0, 0, image.height, image.width);
}

Image tensorToImage(const torch::Tensor& tensor) {
  const auto chw = tensor.squeeze(0);
  Image image(static_cast<int>(chw.size(2)), static_cast<int>(chw.size(1)),
              static_cast<int>(chw.size(0)));
  // Straight into the image's pixels: no intermediate full-frame copy.
  torch::from_blob(image.pixels.data(), {image.height, image.width, image.channels},
                   torch::kFloat32)
      .copy_(chw.permute({1, 2, 0}));
  return image;
}

Denoiser::Denoiser(LoadedModel model) : model_(std::move(model)) { model_.model->eval(); }

Denoiser Denoiser::fromFile(const std::string& path) { return Denoiser(loadModelFile(path)); }

std::vector<std::string> Denoiser::missingBuffers(const std::vector<std::string>& available) const {
  std::vector<std::string> missing;
  for (const auto& name : info().input_buffers)
    if (std::find(available.begin(), available.end(), name) == available.end())
      missing.push_back(name);
  return missing;
}

double Denoiser::bytesPerPixel() const {
  // Skip features live until the decoder uses them; a few full-width tensors
  // are alive at once in a block; the control copy doubles the encoder.
  const UNetConfig& c = info().base;
  double skips = 0.0;
  for (int64_t l = 0; l < c.levels(); ++l)
    skips += double(c.base_channels * c.channel_mults[l] * (c.res_blocks + 1)) / std::pow(4.0, l);
  const double encoders = info().has_control ? 2.0 : 1.0;
  const double working = 8.0 * c.base_channels * c.channel_mults[0];
  const double hint = info().has_control ? 3.0 * info().control.hint_channels : 0.0;
  return 4.0 * 1.5 * (encoders * skips + working + hint);
}

DenoiseResult Denoiser::denoise(const FrameBuffers& frame, const DenoiseOptions& options) const {
  auto missing = missingBuffers(frame.names());
  if (!missing.empty()) {
    std::string list;
    for (const auto& m : missing) list += (list.empty() ? "" : ", ") + m;
    throw std::invalid_argument("model needs buffers the input lacks: " + list);
  }
  if (options.samples < 1) throw std::invalid_argument("samples must be at least 1");
  torch::NoGradGuard noGrad;
  const ModelInfo& mi = info();
  const tonemap::Curve curve = tonemap::curveFromName(mi.tonemap);

  // The radiance in model space is full-frame (the sampler starts from it); the
  // aux inputs, ten times as many channels, are normalized per tile on demand.
  const torch::Tensor cond =
      modelSpaceFromTonemapped(tonemapRadiance(imageToTensor(frame.get("color")), curve));
  auto auxOf = [&](const TileRect& r) {
    return mi.input_buffers.empty()
               ? torch::Tensor()
               : normalizedAuxRegion(frame, mi.input_buffers, curve, r.y0, r.x0, r.height, r.width);
  };

  const NoiseSchedule schedule = options.respacing.empty()
                                     ? mi.samplingSchedule()
                                     : respace(mi.trainingSchedule(), options.respacing);
  const bool regression = mi.objective == Objective::Regression;
  const int64_t skip = options.skip >= 0 ? options.skip : defaultSkip(mi);
  startStep(schedule, skip);  // validates skip against the step count
  const int64_t steps = regression ? 1 : schedule.size() - skip;
  // A regression model is deterministic: more samples would be identical copies.
  const int samples = regression ? 1 : options.samples;

  const int64_t multiple = model_.model->sizeMultiple();
  // Self-attention cost grows with the square of a tile's pixel count: with tiles
  // sized only by the memory budget, one network step on a 1080p frame ran for
  // over 6 minutes on 2 cores. The model also trained on 64 px crops.
  const int64_t tile =
      options.tile > 0
          ? options.tile
          : std::min<int64_t>(kMaxDefaultTile,
                              tileSizeForMemory(options.maxMemoryBytes, bytesPerPixel(), multiple));
  const Tiler tiler(frame.height, frame.width, tile, options.overlap);
  ConditionalDenoiser& net = *model_.model;
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
    so.kind = options.sampler;
    so.eta = options.eta;
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
    torch::Tensor hdr = inverseTonemapRadiance(tonemappedFromModelSpace(sampleOnce(k)), curve);
    if (samples > 1) sumSquares = k == 0 ? hdr * hdr : sumSquares + hdr * hdr;
    sum = k == 0 ? hdr : sum + hdr;  // hdr is a fresh tensor every sample
  }

  DenoiseResult result;
  const double n = samples;
  torch::Tensor mean = sum / n;
  result.color = tensorToImage(
      matchLocalMean(mean, imageToTensor(frame.get("color")), options.meanMatchSigma));
  if (samples > 1) {
    torch::Tensor variance = (sumSquares / n - mean * mean).clamp_min(0.0) * (n / (n - 1));
    result.uncertainty = tensorToImage(variance.sqrt().mean(1, true));
  }
  result.steps = steps;
  result.tileSize = std::min<int64_t>(tile, std::max(frame.width, frame.height));
  result.tileCount = tiler.tiles().size();
  return result;
}

}  // namespace dn
