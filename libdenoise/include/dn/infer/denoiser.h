// The inference pipeline: a model file plus one frame's buffers in, a denoised
// HDR image out. Radiance is clamped and tonemapped, the aux buffers normalized
// (dn/model_inputs.h), the reverse diffusion run with the network applied in
// tiles, and the result inverse-tonemapped back to HDR.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "dn/diffusion/sampler.h"
#include "dn/image.h"
#include "dn/infer/noise_estimate.h"
#include "dn/infer/oidn_filter.h"
#include "dn/io/buffers.h"
#include "dn/nn/model_file.h"

namespace dn {

// The largest tile chosen when DenoiseOptions::tile is 0 (see denoiser.cpp).
constexpr int64_t kMaxDefaultTile = 256;

// Local mean matching radius of the model defaults, in pixels (dn/mean_match.h).
constexpr double kDefaultMeanMatchSigma = 2.0;

// When a Control Module over the OIDN base steers it (models with one).
enum class ControlUse {
  Auto,  // when the base leaves correlated noise (dn/infer/noise_estimate.h)
  Always,
  Never,  // the base alone
};

struct DenoiseOptions {
  std::string respacing;  // "" = the model's default (27 steps); "10" = 10 evenly spaced steps
  int64_t skip = -1;      // noisiest steps to skip; -1 = from the model's default (see below)
  SamplerKind sampler = SamplerKind::Ddpm;
  double eta = 0.0;              // DDIM only
  uint64_t seed = 0;             // same seed, same output
  int samples = 1;               // K > 1: mean of K samples and their standard deviation
  double meanMatchSigma = -1.0;  // local mean matching radius; 0 = off, -1 = from the default
  // Samples per pixel of the input; 0 = unknown (FrameBuffers::samplesPerPixel
  // is used). Defaults are scaled from the model's default_spp to this count.
  int spp = 0;
  // Radiance scale applied before the model and undone after; 0 = autoexposure
  // to the model's exposure_target (none: 1). Dark renders are brightened into
  // the range the model was trained on, where the log curve resolves them.
  double exposure = 0.0;
  int64_t tile = 0;      // network tile size; 0 = derived from maxMemoryBytes, at most 256
  int64_t overlap = 32;  // tile overlap in pixels
  double maxMemoryBytes = 3.0e9;
  // Where the network runs. CUDA runs the pretrained base (BaseKind::Oidn);
  // the diffusion models run on the CPU only (std::invalid_argument otherwise).
  torch::Device device = torch::kCPU;
  // Models over the OIDN base with a diffusion Control Module: the noise levels
  // of the refinement, noisiest first; unset: the model's own; empty: none (the
  // base's estimate as it is).
  std::optional<std::vector<double>> sigmas;
  ControlUse control = ControlUse::Auto;
  // OIDN base with albedo and normal: denoise both first with OIDN's own aux
  // networks, then the colour with its network for clean aux (where the model
  // holds those networks; OIDN's prefilter mode, Blender's "Accurate").
  bool prefilter = true;
  // Prefiltered, with the diffuse light passes: the diffuse part and the rest
  // denoised apart and averaged with the whole (dn/infer/light_paths.h).
  bool lightPaths = true;
  std::function<void(double fraction)> progress;  // 0..1, after every network step
};

// Skip and mean matching radius for one input. A model's defaults are tuned for
// renders as noisy as its tuning frames; a render with less noise starts where
// the forward noise level matches its own (a later step) and trusts its local
// means at a proportionally smaller radius, a noisier one the other way.
// The render's noise relative to the tuning frames' (noiseScale) is
//  - its measured noise (dn/noise_estimate.h) over the model's noise_reference,
//    when the model has one and no --spp was given;
//  - else sqrt(default_spp / spp), from the sample count (Monte Carlo noise
//    falls as 1/sqrt(spp)), when the model has default_spp and the count is known;
//  - else 1: the defaults as they are.
// Explicit skip and radius win.
struct SamplingPlan {
  int64_t skip = 0;
  double meanMatchSigma = kDefaultMeanMatchSigma;
  int spp = 0;            // the count used, 0 = unknown
  double noise = -1;      // the render's measured noise in model space, -1 = not measured
  double noiseScale = 1;  // the render's noise relative to the model's tuning frames
};
// The measured noiseScale is kept in [kMinNoiseScale, kMaxNoiseScale]: the shipped
// model fails when sampling starts near pure noise (docs/model-card.md).
constexpr double kMinNoiseScale = 1.0 / 64.0;
constexpr double kMaxNoiseScale = 3.0;
SamplingPlan planSampling(const ModelInfo& info, const NoiseSchedule& schedule,
                          const DenoiseOptions& options, int fileSpp, double renderNoise = -1);

struct DenoiseResult {
  Image color;          // linear HDR, 3 channels
  Image uncertainty;    // per-pixel standard deviation over samples (samples > 1), 1 channel
  SamplingPlan plan;    // skip and mean matching radius used
  double exposure = 1;  // radiance scale used
  int64_t steps = 0;    // network evaluations per sample
  int64_t tileSize = 0;
  std::size_t tileCount = 0;
  std::vector<std::string> buffersUsed;  // the input buffers the network saw
  bool steered = false;                  // a Control Module steered the base
  bool prefiltered = false;              // albedo and normal were denoised first
  bool lightPathsSplit = false;          // the diffuse part was denoised apart too
  std::optional<NoiseLeft> noiseLeft;    // by the base, when a Control Module could steer it
};

class Denoiser {
 public:
  explicit Denoiser(LoadedModel model);
  static Denoiser fromFile(const std::string& path);  // throws ModelError

  const ModelInfo& info() const { return model_.info; }
  // Buffers the model needs that are not among `available` (empty: ready to
  // denoise); `available` as FrameBuffers::names() or dn::availableBuffers give it.
  std::vector<std::string> missingBuffers(const std::vector<std::string>& available) const;
  // The buffers the model would use from `available`, colour first.
  std::vector<std::string> usableBuffers(const std::vector<std::string>& available) const;
  // Whether a Control Module steers the base on a render with these buffers
  // (it needs its base network's inputs; its extra buffers may be missing).
  bool controlApplies(const std::vector<std::string>& available) const;
  // Estimated activation bytes per pixel of one network evaluation (for tiling).
  double bytesPerPixel() const;

  // Throws std::invalid_argument when buffers are missing (see missingBuffers).
  DenoiseResult denoise(const FrameBuffers& frame, const DenoiseOptions& options) const;

  // The frame's Monte Carlo noise in model space at `exposure` (0: the model's
  // autoexposure), what planSampling compares with the model's noise_reference;
  // denoise() measures at the autoexposure whatever DenoiseOptions::exposure is.
  double measureNoise(const FrameBuffers& frame, double exposure = 0.0) const;

 private:
  // The pretrained base, also under a Control Module (models with BaseKind::Oidn).
  OidnBase oidnBase() const;
  DenoiseResult denoiseWithBase(const FrameBuffers& frame, const DenoiseOptions& options) const;
  DenoiseResult denoiseWithControl(const FrameBuffers& frame, const DenoiseOptions& options) const;

  LoadedModel model_;
};

// (1,C,H,W) float tensor of an interleaved image, and back.
torch::Tensor imageToTensor(const Image& image);
Image tensorToImage(const torch::Tensor& tensor);

}  // namespace dn
