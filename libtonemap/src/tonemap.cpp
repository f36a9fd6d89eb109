#include "dn/tonemap.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <vector>

namespace dn::tonemap {

namespace {
float nonNegative(float v) { return v > 0.0f ? v : 0.0f; }  // also maps NaN to 0
}  // namespace

float gamma(float v) { return kGammaScale * std::pow(nonNegative(v), kGammaExponent); }
float gammaInverse(float t) {
  return std::pow(nonNegative(t) / kGammaScale, 1.0f / kGammaExponent);
}
float log(float v) { return kLogScale * std::log1p(nonNegative(v)); }
float logInverse(float t) { return std::expm1(nonNegative(t) / kLogScale); }
float reinhard(float v) {
  v = nonNegative(v);
  return std::isinf(v) ? 1.0f : v / (1.0f + v);
}
float reinhardInverse(float t) {
  t = std::min(nonNegative(t), 1.0f);
  return t >= 1.0f ? INFINITY : t / (1.0f - t);
}

float srgbEncode(float v) {
  v = nonNegative(v);
  return v <= 0.0031308f ? 12.92f * v : 1.055f * std::pow(v, 1.0f / 2.4f) - 0.055f;
}
float srgbDecode(float e) {
  e = nonNegative(e);
  return e <= 0.04045f ? e / 12.92f : std::pow((e + 0.055f) / 1.055f, 2.4f);
}

float apply(Curve curve, float v) {
  switch (curve) {
    case Curve::Linear:
      return v;
    case Curve::Gamma:
      return gamma(v);
    case Curve::Log:
      return log(v);
    case Curve::Reinhard:
      return reinhard(v);
    case Curve::Srgb:
      return srgbEncode(v);
  }
  return v;
}

float applyInverse(Curve curve, float t) {
  switch (curve) {
    case Curve::Linear:
      return t;
    case Curve::Gamma:
      return gammaInverse(t);
    case Curve::Log:
      return logInverse(t);
    case Curve::Reinhard:
      return reinhardInverse(t);
    case Curve::Srgb:
      return srgbDecode(t);
  }
  return t;
}

void apply(Curve curve, Image& image) {
  for (float& v : image.pixels) v = apply(curve, v);
}

void applyInverse(Curve curve, Image& image) {
  for (float& v : image.pixels) v = applyInverse(curve, v);
}

void clamp(Image& image, float lo, float hi) {
  for (float& v : image.pixels) v = std::isnan(v) ? lo : std::clamp(v, lo, hi);
}

Curve curveFromName(const std::string& name) {
  if (name == "linear") return Curve::Linear;
  if (name == "gamma") return Curve::Gamma;
  if (name == "log") return Curve::Log;
  if (name == "reinhard") return Curve::Reinhard;
  if (name == "srgb") return Curve::Srgb;
  throw std::invalid_argument("unknown tonemap curve '" + name +
                              "' (expected linear, gamma, log, reinhard or srgb)");
}

double exposureForMean(const Image& image, double target, double ceiling, double maxScale) {
  if (image.channels < 3) throw std::invalid_argument("exposureForMean needs 3 channels");
  std::vector<float> luminance;
  luminance.reserve(image.pixelCount());
  for (std::size_t i = 0; i < image.pixels.size(); i += std::size_t(image.channels)) {
    const float* p = &image.pixels[i];
    const float y = 0.2126f * p[0] + 0.7152f * p[1] + 0.0722f * p[2];
    luminance.push_back(std::isfinite(y) && y > 0.0f ? y : 0.0f);
  }
  auto meanAt = [&](double scale) {
    double sum = 0.0;
    for (float y : luminance) sum += std::min(scale * y, ceiling);
    return luminance.empty() ? 0.0 : sum / double(luminance.size());
  };
  // The mean grows with the scale: bisect in log space.
  double lo = 1.0 / maxScale, hi = maxScale;
  if (meanAt(hi) <= target) return meanAt(hi) > 0.0 ? hi : 1.0;
  if (meanAt(lo) >= target) return lo;
  for (int i = 0; i < 50; ++i) {
    const double mid = std::sqrt(lo * hi);
    (meanAt(mid) < target ? lo : hi) = mid;
  }
  return std::sqrt(lo * hi);
}

const char* curveName(Curve curve) {
  switch (curve) {
    case Curve::Linear:
      return "linear";
    case Curve::Gamma:
      return "gamma";
    case Curve::Log:
      return "log";
    case Curve::Reinhard:
      return "reinhard";
    case Curve::Srgb:
      return "srgb";
  }
  return "?";
}

}  // namespace dn::tonemap
