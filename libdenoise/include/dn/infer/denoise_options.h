// What a caller asks of a denoise and what it gets back, for every kind of
// model (dn/infer/denoiser.h): the default pipeline's options first, those of
// the from-scratch diffusion model (an experiment) last.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include <torch/torch.h>

#include "dn/diffusion/sampler.h"
#include "dn/image.h"
#include "dn/infer/noise_estimate.h"

namespace dn {

// When a Control Module over the OIDN base steers it (models with one).
enum class ControlUse {
  Auto,  // when the base leaves correlated noise (dn/infer/noise_estimate.h)
  Always,
  Never,  // the base alone
};

// Quality levels as OIDN names them, each a setting of the prefilter and the
// light-path split below (docs/dndenoise.md has their measured time and quality).
enum class Quality {
  Fast,      // one network on the noisy buffers: OIDN's usual call
  Balanced,  // albedo and normal prefiltered: OIDN's prefilter mode (the default)
  High,      // prefiltered, plus the light-path split where the render has the passes
};
// Quality by name ("fast", "balanced", "high"); std::nullopt for another name.
std::optional<Quality> qualityFromName(const std::string& name);

// The precision of the OIDN networks' inner convolutions; the first and the
// output convolution stay in float.
enum class Precision {
  Float,     // OIDN's result to float rounding (the default)
  BFloat16,  // float accumulation; about twice as fast on CPUs with AMX
  Float16,   // half, as OIDN's CUDA device runs its networks: CUDA only
};
// By name ("float", "bf16", "fp16"); std::nullopt for another name.
std::optional<Precision> precisionFromName(const std::string& name);
const char* precisionName(Precision precision);

// The from-scratch diffusion model's sampling (dn/infer/scratch_diffusion.h);
// other models ignore it.
struct ScratchSampling {
  std::string respacing;  // "" = the model's default (27 steps); "10" = 10 evenly spaced steps
  int64_t skip = -1;      // noisiest steps to skip; -1 = from the model's default
  SamplerKind sampler = SamplerKind::Ddpm;
  double eta = 0.0;              // DDIM only
  double meanMatchSigma = -1.0;  // local mean matching radius; 0 = off, -1 = from the default
  // Samples per pixel of the input; 0 = unknown (FrameBuffers::samplesPerPixel
  // is used). Defaults are scaled from the model's default_spp to this count.
  int spp = 0;
};

// The exposure a caller may set, relative to the model's own autoexposure of
// the frame. Further out the network sees values it was not trained on: the
// default's PSNR on the shipped example falls by 1.4-1.7 dB at 100 and 1/100
// times its autoexposure, by 2.7-6 dB at 1000 and 1/1000 (docs/dndenoise.md),
// and an exposure of 1e-30 once gave outputs of 1e24 from inputs below 1.
constexpr double kMaxExposureRatio = 100;

struct DenoiseOptions {
  // The default pipeline (models over the OIDN base).
  // OIDN base with albedo and normal: denoise both first with OIDN's own aux
  // networks, then the colour with its network for clean aux (OIDN's prefilter
  // mode, Blender's "Accurate").
  bool prefilter = true;
  // Prefiltered, with the diffuse light passes: the diffuse part and the rest
  // denoised apart and averaged with the whole (dn/infer/light_paths.h). Off
  // by default (Quality::Balanced): three more networks, 2.4-2.8 times OIDN's
  // prefilter mode per frame, for 0.04 to 0.18 dB.
  bool lightPaths = false;
  ControlUse control = ControlUse::Auto;
  // OIDN base: the networks' inner convolutions (dn::OidnUNetImpl::useInnerPrecision).
  Precision precision = Precision::Float;
  // Prefiltered: the cleaned albedo and normal in DenoiseResult, for a
  // second denoising of the frame (a sequence's accumulated render); off, a
  // GPU need not copy them back.
  bool returnCleanAux = true;
  // CUDA: cuDNN times its algorithms for each new shape and keeps the fastest
  // (the first frame of a size pays for it). A process-wide setting of LibTorch.
  bool cudnnBenchmark = true;
  // Models with a diffusion Control Module: the noise levels of the
  // refinement, noisiest first; unset: the model's own; empty: none.
  std::optional<std::vector<double>> sigmas;

  // Every model.
  // Radiance scale applied before the network and undone after; 0 = the
  // model's autoexposure. At most kMaxExposureRatio from it either way
  // (std::invalid_argument otherwise).
  double exposure = 0.0;
  uint64_t seed = 0;     // same seed, same output
  int samples = 1;       // K > 1: mean of K samples and their standard deviation
  int64_t tile = 0;      // network tile size; 0 = derived from the memory budget
  int64_t overlap = 32;  // tile overlap in pixels (the from-scratch model; OIDN's own otherwise)
  double maxMemoryBytes = 3.0e9;  // the networks' activations on the CPU, or as below
  // CUDA: the budget is a share of the device's free memory when the frame
  // is denoised (deviceMemoryBudget), not maxMemoryBytes; a large GPU then
  // runs a 4K frame as one tile. False: maxMemoryBytes there too.
  bool budgetFromFreeMemory = true;
  // Where the networks run; the from-scratch model runs on the CPU only.
  torch::Device device = torch::kCPU;
  std::function<void(double fraction)> progress;  // 0..1, after every network step

  ScratchSampling scratch;
};

// The prefilter and light-path settings of a quality level.
void setQuality(DenoiseOptions& options, Quality quality);

// The from-scratch model's sampling plan (dn/infer/scratch_diffusion.h).
struct SamplingPlan {
  int64_t skip = 0;
  double meanMatchSigma = 2.0;
  int spp = 0;            // the count used, 0 = unknown
  double noise = -1;      // the render's measured noise in model space, -1 = not measured
  double noiseScale = 1;  // the render's noise relative to the model's tuning frames
};

struct DenoiseResult {
  Image color;          // linear HDR, 3 channels
  Image uncertainty;    // per-pixel standard deviation over samples (samples > 1), 1 channel
  double exposure = 1;  // radiance scale used
  int64_t steps = 0;    // network evaluations per sample
  int64_t tileSize = 0;
  std::size_t tileCount = 0;
  std::vector<std::string> buffersUsed;  // the input buffers the network saw
  bool steered = false;                  // a Control Module steered the base
  bool prefiltered = false;              // albedo and normal were denoised first
  bool lightPathsSplit = false;          // the diffuse part was denoised apart too
  // Prefiltered: the albedo and normal as the colour network saw them, to
  // denoise the frame again without cleaning them again (FrameBuffers::auxPrefiltered).
  Image cleanAlbedo, cleanNormal;
  std::optional<NoiseLeft> noiseLeft;  // by the base, when a Control Module could steer it
  std::optional<SamplingPlan> plan;    // the from-scratch model's
};

// Throws std::invalid_argument naming both when `requested` (0: automatic) is
// more than kMaxExposureRatio away from the model's `automatic` exposure.
void checkExposure(double requested, double automatic);

}  // namespace dn
