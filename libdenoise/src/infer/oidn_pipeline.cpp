#include "dn/infer/oidn_pipeline.h"

#include <algorithm>
#include <stdexcept>
#include <utility>

#include <ATen/CPUGeneratorImpl.h>

#include "dn/diffusion/refine.h"
#include "dn/infer/control_inputs.h"
#include "dn/infer/device.h"
#include "dn/infer/light_paths.h"
#include "dn/infer/noise_estimate.h"
#include "dn/nn/model_inputs.h"

namespace dn {

namespace {

bool contains(const std::vector<std::string>& names, const std::string& name) {
  return std::find(names.begin(), names.end(), name) != names.end();
}

// The frame's albedo or normal (setName "alb" or "nrm") denoised by the
// base's own network, (1, 3, H, W) on the run's device.
torch::Tensor cleanedAuxTensor(const OidnBase& base, const char* setName, const FrameBuffers& frame,
                               const OidnRunOptions& options) {
  OidnUNet net = base->net(setName);
  net->to(options.device);
  return runOidn(net, oidnInputSet(setName), frame, options).image;
}

Image cleanedAux(const OidnBase& base, const char* setName, const FrameBuffers& frame,
                 const OidnRunOptions& options) {
  return tensorToImage(cleanedAuxTensor(base, setName, frame, options));
}

// The Control Module's own convolutions in channels-last order on a GPU, as
// the base's and their input are (no conversions inside each call); on the
// CPU as they were trained, so that its result there stays bit for bit.
// Called where Module::to just moved the weights, in the same inference
// mode, so that their data is replaced as `to` replaced it.
void useLayoutFor(torch::nn::Module& module, torch::Device device) {
  const auto format =
      device.is_cpu() ? torch::MemoryFormat::Contiguous : torch::MemoryFormat::ChannelsLast;
  torch::NoGradGuard noGrad;
  for (auto& p : module.parameters())
    if (p.dim() == 4 && !p.is_contiguous(format)) p.set_data(p.contiguous(format));
}

torch::ScalarType innerPrecisionOf(Precision precision) {
  switch (precision) {
    case Precision::BFloat16:
      return torch::kBFloat16;
    case Precision::Float16:
      return torch::kHalf;
    default:
      return torch::kFloat;
  }
}

// The settings of the networks' calls for this denoise; half is refused off
// CUDA before any work (LibTorch's CPU convolutions in half are slow or missing).
void applyRunSettings(OidnBase base, const DenoiseOptions& options) {
  if (options.precision == Precision::Float16 && !options.device.is_cuda())
    throw std::invalid_argument("precision fp16: half runs on CUDA only (on the " +
                                options.device.str() + ": float or bf16)");
  useNetworkPrecision(base, options.precision);
  if (options.device.is_cuda()) at::globalContext().setBenchmarkCuDNN(options.cudnnBenchmark);
}

// The networks' memory budget and tile cap: on CUDA by default a share of
// what the device has free (a 4K frame runs whole on a large GPU), else (or
// where this build cannot ask) maxMemoryBytes with OIDN's CPU tiling.
void setMemoryBudget(OidnRunOptions& run, const DenoiseOptions& options) {
  run.maxMemoryBytes = options.maxMemoryBytes;
  if (!options.device.is_cuda() || !options.budgetFromFreeMemory) return;
  if (const std::optional<double> free = freeDeviceMemory(options.device)) {
    run.maxMemoryBytes = deviceMemoryBudget(*free);
    run.maxTilePixels = 0;
  }
}

// The caller's exposure, checked against OIDN's autoexposure of the frame; 0 stays automatic.
float checkedExposure(const DenoiseOptions& options, const FrameBuffers& frame) {
  if (options.exposure > 0)
    checkExposure(options.exposure, tonemap::oidnExposure(frame.get("color")));
  return static_cast<float>(options.exposure);
}

}  // namespace

void useNetworkPrecision(const OidnBase& base, Precision precision) {
  OidnBase(base)->useInnerPrecision(innerPrecisionOf(precision));
}

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

// With the light-path split the diffuse colour is cleaned the same way as the
// albedo and the large network also denoises the diffuse part, guided by it,
// and the rest; the mean of the whole and the sum of the parts is the result.
// The parts are denoised transposed: the network's errors there are less alike
// its errors on the whole, so the mean gains more (docs/dndenoise.md#light-paths).
// Each network run is an equal share of the progress.
OidnRunResult runOidnPrefiltered(const OidnBase& base, const FrameBuffers& frame,
                                 const OidnRunOptions& options, bool splitLightPaths,
                                 FrameBuffers* clean) {
  const int runs = splitLightPaths ? 6 : 3;
  // The images held beside the networks' activations come out of the memory
  // budget (a 4K frame peaked at 4.2 GB without this): the colour and the
  // cleaned buffers, and with the split its parts, their transposed guides
  // and the results; with the gate's uploads, the albedo, normal and depth
  // as sent, kept for it.
  const double heldChannels = (splitLightPaths ? 30.0 : 9.0) + (options.uploads ? 7.0 : 0.0);
  const double held = heldChannels * sizeof(float) * double(frame.width) * frame.height;
  int run = 0;
  auto next = [&]() {
    OidnRunOptions o = options;
    o.maxMemoryBytes = std::max(options.maxMemoryBytes - held, options.maxMemoryBytes / 4);
    const int k = run++;
    if (options.progress) o.progress = [&, k](double f) { options.progress((k + f) / runs); };
    return o;
  };
  const OidnRunOptions albedoRun = next(), normalRun = next();   // in this order: progress
  const OidnInputSet set = oidnInputSet("hdr_calb_cnrm_large");  // a copy: the name is a temporary
  OidnUNet net = base->net(set.name);
  net->to(options.device);
  if (!options.device.is_cpu() && !splitLightPaths) {
    // On a GPU the cleaned albedo and normal stay there for the colour
    // network: the same values, without the copies down to the host and up.
    OidnRunOptions colourRun = next();
    colourRun.onDevice["albedo"] = cleanedAuxTensor(base, "alb", frame, albedoRun).squeeze(0);
    colourRun.onDevice["normal"] = cleanedAuxTensor(base, "nrm", frame, normalRun).squeeze(0);
    if (clean) {
      clean->buffers["albedo"] = tensorToImage(colourRun.onDevice["albedo"].unsqueeze(0));
      clean->buffers["normal"] = tensorToImage(colourRun.onDevice["normal"].unsqueeze(0));
    }
    return runOidn(net, set, frame, colourRun);
  }
  FrameBuffers cleaned = withCleanAux(base, frame, albedoRun, normalRun);
  // Handed to `clean` once no network needs them any more.
  auto keep = [&] {
    if (clean)
      for (const char* aux : {"albedo", "normal"})
        clean->buffers[aux] = std::move(cleaned.buffers.at(aux));
  };
  OidnRunResult whole = runOidn(net, set, cleaned, next());
  if (!splitLightPaths) {
    keep();
    return whole;
  }

  FrameBuffers part;
  part.width = frame.height;
  part.height = frame.width;
  part.buffers["albedo"] = transposed(frame.get("diffuse_color"));
  part.buffers["albedo"] = cleanedAux(base, "alb", part, next());
  part.buffers["normal"] = transposed(cleaned.get("normal"));
  LightPathSplit split = splitDiffuse(frame);  // each part freed once transposed
  part.buffers["color"] = transposed(std::exchange(split.diffuse, Image()));
  const torch::Tensor diffuse = runOidn(net, set, part, next()).image;
  part.buffers["albedo"] = transposed(cleaned.get("albedo"));
  part.buffers["color"] = transposed(std::exchange(split.rest, Image()));
  const torch::Tensor rest = runOidn(net, set, part, next()).image;
  keep();
  whole.image = 0.5 * (whole.image + (diffuse + rest).transpose(2, 3));
  return whole;
}

OidnPipeline::OidnPipeline(const ModelInfo& info, OidnBase base, OidnControlled controlled)
    : info_(info), base_(std::move(base)), controlled_(std::move(controlled)) {
  base_->eval();
  base_->useChannelsLast();
  if (controlled_) controlled_->eval();
}

std::vector<std::string> OidnPipeline::missingBuffers(
    const std::vector<std::string>& available) const {
  return base_->pickSet(available) ? std::vector<std::string>{} : std::vector<std::string>{"color"};
}

bool OidnPipeline::controlApplies(const std::vector<std::string>& available) const {
  if (!controlled_) return false;
  const auto& needed = oidnInputSet(info_.oidn.control.input_set).buffers;
  return std::all_of(needed.begin(), needed.end(),
                     [&](const std::string& name) { return contains(available, name); });
}

std::vector<std::string> OidnPipeline::usableBuffers(
    const std::vector<std::string>& available) const {
  std::vector<std::string> usable;
  if (controlApplies(available)) {
    usable = oidnInputSet(info_.oidn.control.input_set).buffers;
    for (const auto& name : info_.oidn.control.extra_buffers)
      if (contains(available, name)) usable.push_back(name);
  } else if (const OidnInputSet* set = base_->pickSet(available)) {
    usable = set->buffers;
  }
  // The light-path split reads the diffuse passes (DenoiseOptions::lightPaths).
  const auto& passes = diffusePassBuffers();
  if (usable.size() >= 3 && base_->canPrefilter() &&
      std::all_of(passes.begin(), passes.end(),
                  [&](const std::string& name) { return contains(available, name); }))
    for (const auto& name : passes)
      if (!contains(usable, name)) usable.push_back(name);
  return usable;
}

std::vector<std::string> OidnPipeline::buffersToRead(const std::vector<std::string>& available,
                                                     const DenoiseOptions& options) const {
  const std::vector<std::string> usable = usableBuffers(available);
  const OidnInputSet* set = base_->pickSet(available);
  std::vector<std::string> read = set ? set->buffers : std::vector<std::string>{};
  auto add = [&](const std::vector<std::string>& names) {
    for (const auto& name : names)
      if (contains(usable, name) && !contains(read, name)) read.push_back(name);
  };
  if (options.prefilter && options.lightPaths) add(diffusePassBuffers());
  if (controlApplies(available) && options.control == ControlUse::Auto) add(noiseFeatureBuffers());
  if (controlApplies(available) && options.control == ControlUse::Always) add(usable);
  return read;
}

double OidnPipeline::bytesPerPixel() const {
  double most = 0;
  for (const auto& set : info_.oidn.input_sets)
    most = std::max(most, oidnBytesPerPixel(base_->net(set)->config()));
  return most;
}

// Steps 1 to 4; step 5 when the gate opens or the caller asks for it.
DenoiseResult OidnPipeline::denoise(const FrameBuffers& frame,
                                    const DenoiseOptions& options) const {
  applyRunSettings(base_, options);
  const bool control = controlApplies(frame.names());
  // The Control Module's extra buffers are read when it steers (FrameBuffers::unread).
  const std::vector<std::string>& extras = info_.oidn.control.extra_buffers;
  const bool gate = control && options.control == ControlUse::Auto;
  if ((control && options.control == ControlUse::Always) ||
      (gate && frame.correlatedNoise.value_or(false)))
    return denoiseWithControl(withUnread(frame, extras), options);
  // Where the frame's noise is known already, the gate's measure is not taken again.
  DenoiseResult result = denoiseWithBase(frame, options, gate && !frame.correlatedNoise);
  if (!result.noiseLeft || !correlatedNoiseLeft(*result.noiseLeft)) return result;
  DenoiseResult steered = denoiseWithControl(withUnread(frame, extras), options);
  steered.noiseLeft = result.noiseLeft;
  return steered;
}

DenoiseResult OidnPipeline::denoiseWithBase(const FrameBuffers& frame,
                                            const DenoiseOptions& options, bool gate) const {
  c10::InferenceMode inference;
  OidnRunOptions run;
  run.device = options.device;
  run.exposure = checkedExposure(options, frame);
  run.tile = options.tile;
  setMemoryBudget(run, options);
  run.progress = options.progress;
  const bool onHost = options.device.is_cpu();
  FrameUploads uploads(frame, options.device);  // the gate reads what the networks sent
  if (!onHost && gate) run.uploads = &uploads;
  // Off the CPU the host waits for the device once, for the result (its host
  // buffer made while the networks run), and reads the exposure after it.
  run.deferExposureRead = !onHost;
  auto [net, set] = base_->pick(frame.names());
  DenoiseResult result;
  // A second denoising of a frame whose aux the first cleaned (a sequence's
  // accumulated render) runs the default-size network on them, not the large
  // one: about half its time.
  result.prefiltered = options.prefilter && base_->canPrefilter() && set->buffers.size() == 3 &&
                       !frame.auxPrefiltered;
  result.lightPathsSplit = result.prefiltered && options.lightPaths && hasDiffusePasses(frame);
  OidnRunResult out;
  if (result.prefiltered) {
    FrameBuffers clean;
    out = runOidnPrefiltered(base_, frame, run, result.lightPathsSplit,
                             options.returnCleanAux ? &clean : nullptr);
    if (options.returnCleanAux) {
      result.cleanAlbedo = std::move(clean.buffers.at("albedo"));
      result.cleanNormal = std::move(clean.buffers.at("normal"));
    }
  } else {
    net->to(options.device);
    out = runOidn(net, *set, frame, run);
  }
  result.color = tensorToImage(out.image);
  if (!onHost) out.exposure = out.exposureOnDevice.item<float>();
  result.exposure = out.exposure;
  result.steps = result.lightPathsSplit ? 6 : result.prefiltered ? 3 : 1;
  result.tileSize = out.tileSize;
  result.tileCount = out.tileCount;
  result.buffersUsed = set->buffers;
  if (result.lightPathsSplit)
    result.buffersUsed.insert(result.buffersUsed.end(), diffusePassBuffers().begin(),
                              diffusePassBuffers().end());
  if (gate) {
    // Compared where the base works: exposed and PU-encoded, on the run's device.
    const torch::Tensor input = uploads.stored("color") * out.exposure;
    result.noiseLeft = measureNoiseLeft(puEncode(input.nan_to_num(0.0).clamp_min(0.0)),
                                        puEncode(out.image * out.exposure), uploads);
  }
  return result;
}

DenoiseResult OidnPipeline::denoiseWithControl(const FrameBuffers& frame,
                                               const DenoiseOptions& options) const {
  c10::InferenceMode inference;
  const OidnControlConfig& config = info_.oidn.control;
  base_->net(config.input_set);  // the steered network, handed out: in the base's weight layout
  OidnControlled model = controlled_;
  model->to(options.device);
  useLayoutFor(*model->control(), options.device);
  const OidnInputSet& set = oidnInputSet(config.input_set);
  const std::vector<double> sigmas =
      config.diffusion ? options.sigmas.value_or(info_.oidn.sigmas) : std::vector<double>{};
  checkSigmas(sigmas);
  const int samples = sigmas.empty() ? 1 : options.samples;
  const float requested = checkedExposure(options, frame);
  const bool onHost = options.device.is_cpu();
  OidnRunOptions run;
  run.device = options.device;
  run.tile = options.tile;
  setMemoryBudget(run, options);
  OidnRunOptions auxRun = run;
  // The control's encoder copy and the hint network run beside the base.
  run.maxMemoryBytes /= 1.5;
  // On a GPU the colour, the extra buffers and the noise cross once per frame
  // and the hint is made there; on the CPU from each tile's pixels.
  torch::Tensor exposures, extrasOnDevice, presentOnDevice;
  if (onHost) {
    run.exposure = requested > 0 ? requested : tonemap::oidnExposure(frame.get("color"));
    exposures = torch::tensor({run.exposure});
  } else {
    run.onDevice["color"] = bufferOnDevice(frame.get("color"), options.device);
    exposures =
        (requested > 0 ? torch::full({}, requested, torch::TensorOptions().device(options.device))
                       : oidnExposureOnDevice(run.onDevice["color"]))
            .view({1});
    run.exposure = exposures.item<float>();  // before the networks: the host needs it as a number
    std::tie(extrasOnDevice, presentOnDevice) = frameExtrasOnDevice(frame, config, options.device);
  }
  torch::Tensor noise;  // full-frame, so that overlapping tiles agree
  run.network = [&](const torch::Tensor& x, const TileRect& r) {
    auto [extras, present] = onHost ? frameExtras(frame, config, r)
                                    : std::make_pair(crop(extrasOnDevice, r), presentOnDevice);
    const std::vector<int64_t> pad = {0, x.size(3) - r.width, 0, x.size(2) - r.height};
    extras = torch::constant_pad_nd(extras, pad, 0.0);
    // The extras' share of the hint: once per tile, not once per refinement step.
    const torch::Tensor hint = controlHintExtras(config, extras, present, exposures).to(x.device());
    const auto features = model->steered()->encode(x);
    if (!config.diffusion) return model->decode(features, x, hint);
    const torch::Tensor start = model->steered()->decode(features);
    const torch::Tensor tileNoise = torch::constant_pad_nd(crop(noise, r), pad, 0.0).to(x.device());
    const auto floats = x.options().dtype(torch::kFloat);
    return refine(start, tileNoise, sigmas, [&](const torch::Tensor& state, double sigma) {
      return model->decode(features, x,
                           withDiffusionState(hint, state, torch::full({1}, sigma, floats)));
    });
  };

  // A module over the prefilter mode's network sees the guides cleaned, as it trained.
  FrameBuffers cleaned;
  if (set.cleanAux && onHost) cleaned = withCleanAux(base_, frame, auxRun, auxRun);
  if (set.cleanAux && !onHost)  // kept on the device for the steered network
    for (const auto& [aux, setName] : {std::pair("albedo", "alb"), std::pair("normal", "nrm")})
      run.onDevice[aux] = cleanedAuxTensor(base_, setName, frame, auxRun).squeeze(0);
  const FrameBuffers& input = set.cleanAux && onHost ? cleaned : frame;
  torch::Tensor sum, sumSquares;
  OidnRunResult out;
  for (int k = 0; k < samples; ++k) {
    auto generator = at::detail::createCPUGenerator(options.seed + uint64_t(k));
    // Drawn on the CPU, so that every device refines from the same noise.
    noise = torch::randn({1, 3, frame.height, frame.width}, generator).to(options.device);
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

}  // namespace dn
