#include "dn/infer/denoiser.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <utility>

#include <ATen/CPUGeneratorImpl.h>

#include "dn/diffusion/refine.h"
#include "dn/infer/control_inputs.h"
#include "dn/infer/highlights.h"
#include "dn/infer/light_paths.h"
#include "dn/infer/mean_match.h"
#include "dn/infer/model_inputs.h"
#include "dn/infer/noise_estimate.h"
#include "dn/infer/tiler.h"

namespace dn {

namespace {

double noteOr(const ModelInfo& info, const std::string& key, double fallback) {
  auto it = info.notes.find(key);
  return it == info.notes.end() ? fallback : std::stod(it->second);
}

// The image mirrored about its diagonal: x and y swapped.
Image transposed(const Image& image) {
  Image out(image.height, image.width, image.channels);
  for (int y = 0; y < image.height; ++y)
    for (int x = 0; x < image.width; ++x)
      std::copy_n(image.pixel(x, y), image.channels, out.pixel(y, x));
  return out;
}

// The frame's albedo or normal (setName "alb" or "nrm") denoised by the base's own network.
Image cleanedAux(const OidnBase& base, const char* setName, const FrameBuffers& frame,
                 const OidnRunOptions& options) {
  OidnUNet net = base->net(setName);
  net->to(options.device);
  return tensorToImage(runOidn(net, oidnInputSet(setName), frame, options).image);
}

// The frame's colour with its albedo and normal cleaned: the inputs of the
// prefilter mode's colour network.
FrameBuffers withCleanAux(const OidnBase& base, const FrameBuffers& frame,
                          const OidnRunOptions& albedoRun, const OidnRunOptions& normalRun) {
  FrameBuffers clean;
  clean.width = frame.width;
  clean.height = frame.height;
  clean.buffers["color"] = frame.get("color");
  clean.buffers["albedo"] = cleanedAux(base, "alb", frame, albedoRun);
  clean.buffers["normal"] = cleanedAux(base, "nrm", frame, normalRun);
  return clean;
}

// OIDN's prefilter mode: the albedo and the normal are denoised by their own
// networks, then the colour by the large network trained with noise-free albedo
// and normal. With the light-path split (dn/infer/light_paths.h) the diffuse
// colour is cleaned the same way and the large network also denoises the
// diffuse part, guided by it, and the rest; the mean of the whole and the sum
// of the parts is the result. The parts are denoised transposed: the network's
// errors there are less alike its errors on the whole, so the mean gains more
// (docs/dndenoise.md#light-paths). Each network run is an equal share of the progress.
OidnRunResult runOidnPrefiltered(const OidnBase& base, const FrameBuffers& frame,
                                 const OidnRunOptions& options, bool splitLightPaths) {
  const int runs = splitLightPaths ? 6 : 3;
  // The images held beside the networks' activations come out of the memory
  // budget (a 4K frame peaked at 4.2 GB without this): the colour and the
  // cleaned buffers, and with the split its parts, their transposed guides
  // and the results.
  const double held =
      (splitLightPaths ? 10.0 : 3.0) * 3 * sizeof(float) * double(frame.width) * frame.height;
  int run = 0;
  auto next = [&]() {
    OidnRunOptions o = options;
    o.maxMemoryBytes = std::max(options.maxMemoryBytes - held, options.maxMemoryBytes / 4);
    const int k = run++;
    if (options.progress) o.progress = [&, k](double f) { options.progress((k + f) / runs); };
    return o;
  };
  const OidnRunOptions albedoRun = next(), normalRun = next();  // in this order: progress
  const FrameBuffers clean = withCleanAux(base, frame, albedoRun, normalRun);
  const OidnInputSet& set = oidnInputSet("hdr_calb_cnrm_large");
  OidnUNet net = base->net(set.name);
  net->to(options.device);
  OidnRunResult whole = runOidn(net, set, clean, next());
  if (!splitLightPaths) return whole;

  FrameBuffers part;
  part.width = frame.height;
  part.height = frame.width;
  part.buffers["albedo"] = transposed(frame.get("diffuse_color"));
  part.buffers["albedo"] = cleanedAux(base, "alb", part, next());
  part.buffers["normal"] = transposed(clean.get("normal"));
  LightPathSplit split = splitDiffuse(frame);  // each part freed once transposed
  part.buffers["color"] = transposed(std::exchange(split.diffuse, Image()));
  const torch::Tensor diffuse = runOidn(net, set, part, next()).image;
  part.buffers["albedo"] = transposed(clean.get("albedo"));
  part.buffers["color"] = transposed(std::exchange(split.rest, Image()));
  const torch::Tensor rest = runOidn(net, set, part, next()).image;
  whole.image = 0.5 * (whole.image + (diffuse + rest).transpose(2, 3));
  return whole;
}

// Forward noise at a step in image units, sqrt((1 - alpha_bar) / alpha_bar).
double noiseLevel(const NoiseSchedule& schedule, int64_t step) {
  const double ab = schedule.alphaBar(step);
  return std::sqrt((1.0 - ab) / ab);
}

double exposureFor(const ModelInfo& info, const Image& color, double requested) {
  if (requested > 0.0) return requested;
  const double target = noteOr(info, "exposure_target", 0);
  return target > 0 ? tonemap::exposureForMean(color, target) : 1.0;
}

// The render's radiance as the network sees it: exposed, clamped, tonemapped, in [-1, 1].
torch::Tensor modelSpaceRadiance(const ModelInfo& info, const Image& color, double exposure) {
  return modelSpaceFromTonemapped(
      tonemapRadiance(imageToTensor(color) * exposure, tonemap::curveFromName(info.tonemap)));
}

}  // namespace

SamplingPlan planSampling(const ModelInfo& info, const NoiseSchedule& schedule,
                          const DenoiseOptions& options, int fileSpp, double renderNoise) {
  SamplingPlan plan;
  const double defaultSpp = noteOr(info, "default_spp", 0);
  const double noiseReference = noteOr(info, "noise_reference", 0);
  plan.spp = options.spp > 0 ? options.spp : fileSpp;
  plan.noise = renderNoise;
  if (options.spp <= 0 && noiseReference > 0 && renderNoise >= 0)
    plan.noiseScale = std::clamp(renderNoise / noiseReference, kMinNoiseScale, kMaxNoiseScale);
  else if (defaultSpp > 0 && plan.spp > 0)
    plan.noiseScale = std::sqrt(defaultSpp / plan.spp);
  if (options.skip >= 0) {
    plan.skip = options.skip;
  } else {
    // The model's default start, as a noise level on its own sampling schedule,
    // carried over to the schedule in use and scaled to the input's noise.
    const NoiseSchedule defaults = info.samplingSchedule();
    const double level =
        noiseLevel(defaults, startStep(defaults, int64_t(noteOr(info, "default_skip", 0)))) *
        plan.noiseScale;
    plan.skip = maxSkipForNoise(schedule, level * (1.0 - 1e-9));  // exact default: its own skip
  }
  plan.meanMatchSigma = options.meanMatchSigma >= 0 ? options.meanMatchSigma
                                                    : kDefaultMeanMatchSigma * plan.noiseScale;
  return plan;
}

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

Denoiser::Denoiser(LoadedModel model) : model_(std::move(model)) {
  if (model_.oidnControlled) model_.oidnControlled->eval();
  if (model_.oidn) {
    model_.oidn->eval();
    model_.oidn->useChannelsLast();
  } else {
    model_.model->eval();
  }
}

Denoiser Denoiser::fromFile(const std::string& path) { return Denoiser(loadModelFile(path)); }

double Denoiser::measureNoise(const FrameBuffers& frame, double exposure) const {
  torch::NoGradGuard noGrad;
  const Image& color = frame.get("color");
  return estimateNoise(modelSpaceRadiance(info(), color, exposureFor(info(), color, exposure)),
                       frame);
}

std::vector<std::string> Denoiser::missingBuffers(const std::vector<std::string>& available) const {
  if (info().base_kind == BaseKind::Oidn)
    return model_.oidn->pick(available).second ? std::vector<std::string>{}
                                               : std::vector<std::string>{"color"};
  std::vector<std::string> missing;
  for (const auto& name : info().input_buffers)
    if (std::find(available.begin(), available.end(), name) == available.end())
      missing.push_back(name);
  return missing;
}

bool Denoiser::controlApplies(const std::vector<std::string>& available) const {
  if (!model_.oidnControlled) return false;
  for (const auto& name : oidnInputSet(info().oidn.control.input_set).buffers)
    if (std::find(available.begin(), available.end(), name) == available.end()) return false;
  return true;
}

std::vector<std::string> Denoiser::usableBuffers(const std::vector<std::string>& available) const {
  auto present = [&](const std::string& name) {
    return std::find(available.begin(), available.end(), name) != available.end();
  };
  std::vector<std::string> usable;
  if (controlApplies(available)) {
    usable = oidnInputSet(info().oidn.control.input_set).buffers;
    for (const auto& name : info().oidn.control.extra_buffers)
      if (present(name)) usable.push_back(name);
  } else if (info().base_kind == BaseKind::Oidn) {
    const OidnInputSet* set = model_.oidn->pick(available).second;
    if (set) usable = set->buffers;
  } else {
    usable = {"color"};
    usable.insert(usable.end(), info().input_buffers.begin(), info().input_buffers.end());
    return usable;
  }
  // The light-path split reads the diffuse passes (DenoiseOptions::lightPaths).
  const OidnBase base = oidnBase();
  if (usable.size() >= 3 && base->canPrefilter() &&
      std::all_of(diffusePassBuffers().begin(), diffusePassBuffers().end(), present))
    for (const auto& name : diffusePassBuffers())
      if (std::find(usable.begin(), usable.end(), name) == usable.end()) usable.push_back(name);
  return usable;
}

OidnBase Denoiser::oidnBase() const {
  return model_.oidnControlled ? model_.oidnControlled->base() : model_.oidn;
}

double Denoiser::bytesPerPixel() const {
  if (info().base_kind == BaseKind::Oidn) {
    double most = 0;
    for (const auto& set : info().oidn.input_sets)
      most = std::max(most, oidnBytesPerPixel(model_.oidn->net(set)->config()));
    return most;
  }
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
  if (info().base_kind == BaseKind::Oidn) return denoiseWithBase(frame, options);
  if (!options.device.is_cpu())
    throw std::invalid_argument("this diffusion model runs on the CPU only (use --device cpu)");
  torch::NoGradGuard noGrad;
  const ModelInfo& mi = info();
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

  const NoiseSchedule schedule = options.respacing.empty()
                                     ? mi.samplingSchedule()
                                     : respace(mi.trainingSchedule(), options.respacing);
  const bool regression = mi.objective == Objective::Regression;
  // The noise is measured only where the plan uses it, and at the model's own
  // exposure, as its noise_reference was: --exposure changes what the network
  // sees, not how noisy the render is.
  const bool measure = mi.notes.count("noise_reference") && options.spp <= 0 &&
                       (options.skip < 0 || options.meanMatchSigma < 0);
  // At the autoexposure (the default) the network's input is what is measured.
  const double noise = !measure                ? -1.0
                       : options.exposure <= 0 ? estimateNoise(cond, frame)
                                               : measureNoise(frame);
  const SamplingPlan plan = planSampling(mi, schedule, options, frame.samplesPerPixel, noise);
  const int64_t skip = plan.skip;
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

DenoiseResult Denoiser::denoiseWithControl(const FrameBuffers& frame,
                                           const DenoiseOptions& options) const {
  c10::InferenceMode inference;
  const ModelInfo& mi = info();
  OidnControlled model = model_.oidnControlled;
  model->to(options.device);
  const OidnControlConfig& config = mi.oidn.control;
  const OidnInputSet& set = oidnInputSet(config.input_set);
  const std::vector<double> sigmas =
      config.diffusion ? options.sigmas.value_or(mi.oidn.sigmas) : std::vector<double>{};
  checkSigmas(sigmas);
  const int samples = sigmas.empty() ? 1 : options.samples;
  const float exposure =
      options.exposure > 0 ? float(options.exposure) : tonemap::oidnExposure(frame.get("color"));
  const torch::Tensor exposures = torch::tensor({exposure});

  OidnRunOptions run;
  run.device = options.device;
  run.exposure = exposure;
  run.tile = options.tile;
  OidnRunOptions auxRun = run;
  auxRun.maxMemoryBytes = options.maxMemoryBytes;
  // The control's encoder copy and the hint network run beside the base.
  run.maxMemoryBytes = options.maxMemoryBytes / 1.5;
  torch::Tensor noise;  // full-frame, so that overlapping tiles agree
  run.network = [&](const torch::Tensor& x, const TileRect& r) {
    // The hint is made on the CPU (the PU curve runs there) and moved.
    auto [extras, present] = frameExtras(frame, config, r);
    const std::vector<int64_t> pad = {0, x.size(3) - r.width, 0, x.size(2) - r.height};
    extras = torch::constant_pad_nd(extras, pad, 0.0);
    const auto features = model->steered()->encode(x);
    if (!config.diffusion)
      return model->decode(features, x,
                           controlHint(config, extras, present, exposures).to(x.device()));
    const torch::Tensor start = model->steered()->decode(features);
    const torch::Tensor tileNoise =
        torch::constant_pad_nd(noise.narrow(2, r.y0, r.height).narrow(3, r.x0, r.width), pad, 0.0)
            .to(x.device());
    return refine(start, tileNoise, sigmas, [&](const torch::Tensor& state, double sigma) {
      const torch::Tensor hint =
          controlHint(config, extras, present, exposures, state.cpu(), torch::full({1}, sigma));
      return model->decode(features, x, hint.to(x.device()));
    });
  };

  // A module over the prefilter mode's network sees the guides cleaned, as it trained.
  FrameBuffers cleaned;
  if (set.cleanAux) cleaned = withCleanAux(oidnBase(), frame, auxRun, auxRun);
  const FrameBuffers& input = set.cleanAux ? cleaned : frame;
  torch::Tensor sum, sumSquares;
  OidnRunResult out;
  for (int k = 0; k < samples; ++k) {
    auto generator = at::detail::createCPUGenerator(options.seed + uint64_t(k));
    noise = torch::randn({1, 3, frame.height, frame.width}, generator);
    if (options.progress) run.progress = [&, k](double f) { options.progress((k + f) / samples); };
    OidnUNet steered = model->steered();
    out = runOidn(steered, set, input, run);
    sum = k == 0 ? out.image : sum + out.image;
    if (samples > 1) sumSquares = k == 0 ? out.image.square() : sumSquares + out.image.square();
  }
  DenoiseResult result;
  const double n = samples;
  result.color = tensorToImage(sum / n);
  if (samples > 1) {
    const torch::Tensor mean = sum / n;
    torch::Tensor variance = (sumSquares / n - mean * mean).clamp_min(0.0) * (n / (n - 1));
    result.uncertainty = tensorToImage(variance.sqrt().mean(1, true));
  }
  result.exposure = out.exposure;
  result.prefiltered = set.cleanAux;
  result.steps = (set.cleanAux ? 3 : 1) + int64_t(sigmas.size());
  result.steered = true;
  result.tileSize = out.tileSize;
  result.tileCount = out.tileCount;
  result.buffersUsed = usableBuffers(frame.names());
  return result;
}

DenoiseResult Denoiser::denoiseWithBase(const FrameBuffers& frame,
                                        const DenoiseOptions& options) const {
  const bool control = controlApplies(frame.names());
  if (control && options.control == ControlUse::Always) return denoiseWithControl(frame, options);
  DenoiseResult result;
  {
    c10::InferenceMode inference;
    OidnBase base = oidnBase();
    OidnRunOptions run;
    run.device = options.device;
    run.exposure = static_cast<float>(options.exposure);
    run.tile = options.tile;
    run.maxMemoryBytes = options.maxMemoryBytes;
    run.progress = options.progress;
    auto [net, set] = base->pick(frame.names());
    result.prefiltered = options.prefilter && base->canPrefilter() && set->buffers.size() == 3;
    result.lightPathsSplit = result.prefiltered && options.lightPaths && hasDiffusePasses(frame);
    OidnRunResult out;
    if (result.prefiltered) {
      out = runOidnPrefiltered(base, frame, run, result.lightPathsSplit);
    } else {
      net->to(options.device);
      out = runOidn(net, *set, frame, run);
    }
    result.color = tensorToImage(out.image);
    result.exposure = out.exposure;
    result.steps = result.lightPathsSplit ? 6 : result.prefiltered ? 3 : 1;
    result.tileSize = out.tileSize;
    result.tileCount = out.tileCount;
    result.buffersUsed = set->buffers;
    if (result.lightPathsSplit)
      result.buffersUsed.insert(result.buffersUsed.end(), diffusePassBuffers().begin(),
                                diffusePassBuffers().end());
    if (control && options.control == ControlUse::Auto) {
      // Compared where the base works: exposed and PU-encoded.
      const torch::Tensor input = imageToTensor(frame.get("color")) * out.exposure;
      result.noiseLeft = measureNoiseLeft(puEncode(input.nan_to_num(0.0).clamp_min(0.0)),
                                          puEncode(out.image * out.exposure), frame);
    }
  }
  if (options.control != ControlUse::Auto || !result.noiseLeft ||
      !correlatedNoiseLeft(*result.noiseLeft))
    return result;
  DenoiseResult steered = denoiseWithControl(frame, options);
  steered.noiseLeft = result.noiseLeft;
  return steered;
}

}  // namespace dn
