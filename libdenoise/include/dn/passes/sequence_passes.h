// Light passes on a frame sequence (dndenoise --passes on shot.#.exr with
// motion vectors): each frame's passes denoised alone, as for one frame, then
// filtered over the window with the beauty's weights (the same neighbours,
// reprojection and per-pixel weights: dn::temporal::Sequence's companions),
// Diffuse Color too; each light pass's render accumulated with the same
// weights, denoised again, averaged with the past frames' and blended in, as
// the beauty's is; and the residual set to the frame's denoised beauty minus
// the rest, so the renderer's rule still holds exactly. The residual then
// holds what the passes do not explain, not their flicker.
#pragma once

#include <map>
#include <string>

#include "dn/passes/joint_denoise.h"
#include "dn/temporal/sequence.h"

namespace dn {

// Which passes are filtered over time.
enum class PassesOverTime {
  // The light passes and the colour passes of the terms whose light follows the
  // surface (Diffuse Color: it closes the sum where a textured surface moves);
  // those of view-dependent light (Glossy Color) as denoised alone (the default,
  // measured: docs/RESULTS.md).
  Light,
  All,  // the colours of view-dependent light too
  Off,  // none: every pass as denoised alone, the residual takes the beauty's filtering
};

struct SequencePassOptions {
  PassDenoiseOptions denoise;
  PassesOverTime overTime = PassesOverTime::Light;
  // The light passes filtered over time also accumulated as the beauty's
  // render is, denoised again (the first-hit albedo guide) by the
  // default-size network as the beauty's is, and blended in by its share:
  // one network run more a pass and frame, about half a large one. On the
  // production-scale tuning half, +0.07 dB a light pass on the moving shots
  // (the large network: +0.06).
  bool accumulated = true;
  // The precision of that second denoising (secondDenoisingPrecision).
  Precision accumulatedPrecision = Precision::Float;
};

// The precision of a sequence's second denoisings (its accumulated renders,
// the beauty's and the light passes' alike, so that the residual closing
// their sum holds no rounding of one that the other lacks) where the light
// passes are filtered over time, for a run in `precision` on `device`:
// bfloat16 where that is float, on a CPU that computes bfloat16 natively (AMX
// or AVX-512 BF16), unless `precisionGiven` (one precision throughout, as
// asked); else `precision`. The second denoising is at most
// TemporalOptions::accumulatedShare of each result: on the production-scale
// tuning shots bfloat16 moved the light passes by 0.03 dB at most and the
// beauty by 0.07 dB at most, and took 0.93 of the time of --passes on a
// sequence (docs/dndenoise.md, Light passes on a sequence).
Precision secondDenoisingPrecision(Precision precision, const torch::Device& device,
                                   bool precisionGiven);

// A frame's passes (readLightPasses of the file's layout), each denoised
// alone, the residual left out (the sum closes it), marked for filtering over
// time by options.overTime, the light passes with their renders where
// options.accumulated; and those renders, accumulated, denoised again. Throws
// IoError with one line naming the file when it has no light passes or lacks
// albedo and normal.
temporal::CompanionMaker lightPassCompanions(const OidnBase& base,
                                             const SequencePassOptions& options);

// Per pixel, the share of `frame`'s light (its colour) in the view-dependent
// passes of `path` (LightPassSpec::viewDependent: glossy and transmission,
// each times its term's colour), both averaged over a (2 radius + 1)^2 box of
// the noisy render, in [0, 1]: the temporal filter's
// WindowFrame::viewDependent. Empty where the file has no such passes.
// The passes are taken from frame.extra where read there (viewDependentChannels).
Image viewDependentShare(const std::string& path, const FrameBuffers& frame, int radius = 2);

// The channels viewDependentShare reads of `path`, for ReadOptions::extra:
// read with the frame's buffers, the file is decoded once. `layerPrefix`: the
// colour's (layerPrefixOf).
ChannelGroups viewDependentChannels(const std::string& path, const std::string& layerPrefix);

// The frame's passes as filtered (Sequence's companions of lightPassCompanions)
// made to recombine to `denoisedBeauty`, and named for writing.
PassesResult passesOfSequenceFrame(const std::string& path, const FrameBuffers& frame,
                                   const std::map<std::string, Image>& filtered,
                                   const Image& denoisedBeauty, const SequencePassOptions& options);

}  // namespace dn
