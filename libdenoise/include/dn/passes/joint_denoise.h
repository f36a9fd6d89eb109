// Denoised light passes that add up to the denoised beauty. Each pass is
// denoised by OIDN's networks with the guide that suits it (colour passes by
// the albedo network, as albedo-like buffers; light passes by the large
// prefilter-mode network with the cleaned normal and albedo); then the
// residual is set to the denoised beauty minus the sum of the others, so the
// renderer's rule (dn/passes/light_passes.h) gives the denoised beauty back
// to float rounding and no pass carries another's error or the beauty's.
// ShareRule offers, for measurement, sharing that difference over the passes.
#pragma once

#include <map>
#include <string>
#include <vector>

#include "dn/image.h"
#include "dn/infer/denoise_options.h"
#include "dn/infer/oidn_filter.h"
#include "dn/io/buffers.h"
#include "dn/nn/oidn_unet.h"
#include "dn/passes/light_passes.h"

namespace dn {

// The albedo a light pass is denoised with.
// Measured (docs/RESULTS.md#denoised-light-passes): the first-hit albedo.
enum class LightPassGuide {
  Albedo,     // the cleaned first-hit albedo, as OIDN run on the pass alone would take
  TermColor,  // the cleaned colour pass of its term (the cleaned albedo for terms without one)
};

// How the colour passes (DiffCol, ...) are denoised. Measured: the albedo network.
enum class ColorPassDenoise {
  AlbedoNetwork,  // OIDN's albedo network, as the albedo-like buffers they are
  Guided,         // OIDN's large network, guided by the cleaned albedo and normal
};

// How the beauty's difference from the sum of the parts is shared out.
// Measured (docs/RESULTS.md#denoised-light-passes): sharing it over the light
// passes gains up to 0.5 dB on some passes and loses up to 3.7 dB on others
// (a clean Environment, Glossy Indirect): the difference carries the beauty's
// own error. So by default no pass takes it: the residual does.
enum class ShareRule {
  None,           // the residual takes it: every pass stays as denoised alone
  Magnitude,      // by each part's denoised magnitude (in beauty units)
  RelativeNoise,  // by magnitude x the part's relative noise over a wide box
  Error,          // by each part's estimated squared error (local mean of noisy - denoised)
};

struct PassDenoiseOptions {
  OidnRunOptions run;                      // device, tiling and memory of every network run
  Precision precision = Precision::Float;  // of every network run (DenoiseOptions::precision)
  LightPassGuide guide = LightPassGuide::Albedo;
  ColorPassDenoise colorPasses = ColorPassDenoise::AlbedoNetwork;
  ShareRule share = ShareRule::None;
  int errorRadius = 2;  // ShareRule::Error: box radius of the local mean, pixels
  int noiseRadius = 8;  // ShareRule::RelativeNoise: box radius, pixels
  // The residual denoised alone too (two network runs: its positive and
  // negative parts). Only a sharing rule reads it: with ShareRule::None the
  // sum closes it (dndenoise leaves it out).
  bool residualAlone = true;
};

struct DenoisedPasses {
  LightPassImages passes;  // by key, the residual included: recombine() is the beauty
  // Each pass before the sharing: denoised alone (on a sequence, filtered over
  // time); the residual only where denoised alone (residualAlone).
  LightPassImages independent;
  double maxRelativeError = 0;  // recombine(passes) against the denoised beauty
};

// A light pass (HDR, non-negative) denoised by OIDN's large network (or the
// default-size one) with cleaned guides; all zero stays so, without a run.
Image denoiseLight(const OidnBase& base, const Image& light, const Image& albedo,
                   const Image& normal, const OidnRunOptions& run, bool large = true);

// Each pass of `noisy` (readLightPasses of `frame`, which holds albedo and
// normal) denoised alone, the residual included, with the guides of
// `options.guide`: the first step of denoiseLightPasses.
LightPassImages denoisePassesApart(const OidnBase& base, const FrameBuffers& frame,
                                   const LightPassLayout& layout, const LightPassImages& noisy,
                                   const PassDenoiseOptions& options);

// The second: `apart` made to recombine to `denoisedBeauty`, the difference
// shared out by options.share, the residual closing the sum.
DenoisedPasses shareToBeauty(const LightPassLayout& layout, const LightPassImages& noisy,
                             const LightPassImages& apart, const Image& denoisedBeauty,
                             const PassDenoiseOptions& options);

// Both steps. Denoises `noisy` (readLightPasses of `frame`, which holds albedo and normal)
// consistently with `denoisedBeauty`, the colour's denoised result. `base`
// must hold OIDN's prefilter-mode networks (OidnBaseImpl::canPrefilter).
DenoisedPasses denoiseLightPasses(const OidnBase& base, const FrameBuffers& frame,
                                  const LightPassLayout& layout, const LightPassImages& noisy,
                                  const Image& denoisedBeauty, const PassDenoiseOptions& options);

// The layers to write beside the noisy passes, by full layer name: the view
// layer, the rule's output prefix and the file's pass name, e.g.
// "ViewLayer.Denoised Diffuse Direct" (and "ViewLayer.Denoised Residual").
std::map<std::string, Image> denoisedPassLayers(const LightPassLayout& layout,
                                                const LightPassImages& passes);

// The light passes of `path` in the view layer of `frame` (its colour's
// layer). Throws IoError with one line naming `path` when it has no light
// passes or `frame` lacks albedo and normal.
LightPassLayout passLayoutOfFrame(const std::string& path, const FrameBuffers& frame);

// Mean over a (2r+1)^2 box, per channel, the box clipped at the borders.
Image boxMean(const Image& image, int r);

// For dndenoise --passes: the file's light passes found, read, denoised
// against `denoisedBeauty` and named for writing. Throws IoError with one line
// naming `path` when it has no light passes or lacks albedo and normal.
struct PassesResult {
  LightPassLayout layout;
  DenoisedPasses denoised;
  std::map<std::string, Image> layers;
};
PassesResult denoisePassesOfFile(const OidnBase& base, const std::string& path,
                                 const FrameBuffers& frame, const Image& denoisedBeauty,
                                 const PassDenoiseOptions& options = {});

// The light passes of `path` (header only; empty layout when none) in view
// layer `viewLayer` ("": the file's only one, Blender's "Composite" aside),
// for the check before any work.
LightPassLayout lightPassesOfFile(const std::string& path, const std::string& viewLayer = "");

// Throws IoError with one line naming `path` when it has no light passes.
void requireLightPasses(const std::string& path, const std::string& viewLayer = "");

// The network runs of the passes as `denoise` runs the beauty's (device,
// tiling, memory); the residual not denoised alone (the sum closes it); the
// rest as the defaults.
PassDenoiseOptions passOptionsFor(const DenoiseOptions& denoise);

// The pretrained OIDN base of a model file (throws IoError naming the file
// when the model has none or lacks the prefilter mode's networks).
OidnBase oidnBaseOfModel(const std::string& modelPath);
// Throws IoError naming `modelPath` when `base` (null for models not over
// OIDN's networks) lacks the prefilter mode's networks the passes need.
void requirePrefilterNetworks(const OidnBase& base, const std::string& modelPath);

}  // namespace dn
