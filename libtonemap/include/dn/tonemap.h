// Tonemapping curves used by the denoiser and the metrics, each with its exact
// inverse. The model works in the log (or gamma) range; metrics use Reinhard.
#pragma once

#include <string>

#include "dn/image.h"

namespace dn::tonemap {

constexpr float kHdrMax = 6.0f;       // radiance is clamped to [0, 6] (paper)
constexpr float kGammaScale = 0.47f;  // gamma curve: A * v^g
constexpr float kGammaExponent = 1.0f / 2.4f;
constexpr float kLogScale = 0.51f;  // log curve: A * log(1 + v)

enum class Curve { Linear, Gamma, Log, Reinhard, Srgb };

float gamma(float v);
float gammaInverse(float t);
float log(float v);
float logInverse(float t);
float reinhard(float v);
float reinhardInverse(float t);
float srgbEncode(float linear);
float srgbDecode(float encoded);
// OIDN's HDR transfer function: a perceptually uniform encoding (a linear toe,
// a power segment, then a log) scaled so that half's largest value, 65504,
// maps to 1. The pretrained base (dn/nn/oidn_unet.h) works in this range.
float pu(float v);
float puInverse(float t);

float apply(Curve curve, float v);
float applyInverse(Curve curve, float t);

// In-place, over every channel of the image. Negative inputs map through the
// curves as 0 (all curves are defined on radiance >= 0).
void apply(Curve curve, Image& image);
void applyInverse(Curve curve, Image& image);
void clamp(Image& image, float lo, float hi);

// Autoexposure: the scale s with mean(min(s * luminance, ceiling)) = target over
// the first three channels (Rec. 709 luminance; NaN, Inf and negatives count as
// 0), so lights and fireflies above the ceiling count once. Clamped to
// [1 / maxScale, maxScale]; 1 for an image with no light.
double exposureForMean(const Image& image, double target, double ceiling = kHdrMax,
                       double maxScale = 64.0);

// OIDN's autoexposure: 0.18 over the geometric mean of the mean luminance of
// 16x16-pixel bins (bins of luminance at most 1e-8 left out; NaN and negatives
// count as 0); 1 when every bin is dark. Scales HDR radiance before pu().
float oidnExposure(const Image& color);

// "gamma", "log", "reinhard", "srgb", "linear"; throws std::invalid_argument.
Curve curveFromName(const std::string& name);
const char* curveName(Curve curve);

}  // namespace dn::tonemap
