#include "dn/tonemap.h"

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <stdexcept>
#include <vector>

#include "dn/pu_curve.h"

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

namespace {
using namespace pu_curve;

float puUnscaled(float y) {
  if (y <= kY0) return kA * y;
  if (y <= kY1) return kB * std::pow(y, kC) + kD;
  return kE * std::log(y + kF) + kG;
}

float puUnscaledInverse(float x) {
  if (x <= kX0) return x / kA;
  if (x <= kX1) return std::pow((x - kD) / kB, 1.0f / kC);
  return std::exp((x - kG) / kE) - kF;
}

const float kPuNorm = puUnscaled(kHalfMax);
}  // namespace

float pu(float v) { return puUnscaled(v) / kPuNorm; }
float puInverse(float t) { return puUnscaledInverse(t * kPuNorm); }

float oidnExposure(const Image& color) {
  constexpr int kBin = 16;
  const int binsY = (color.height + kBin - 1) / kBin, binsX = (color.width + kBin - 1) / kBin;
  double logSum = 0.0;
  int count = 0;
  for (int by = 0; by < binsY; ++by)
    for (int bx = 0; bx < binsX; ++bx) {
      const int y0 = by * color.height / binsY, y1 = (by + 1) * color.height / binsY;
      const int x0 = bx * color.width / binsX, x1 = (bx + 1) * color.width / binsX;
      float sum = 0.0f;
      for (int y = y0; y < y1; ++y)
        for (int x = x0; x < x1; ++x) {
          const float* p = color.pixel(x, y);
          auto clean = [](float v) {
            return std::isfinite(v) ? std::max(v, 0.0f) : (v > 0 ? FLT_MAX : 0.0f);
          };
          const float g = color.channels >= 3 ? p[1] : p[0], b = color.channels >= 3 ? p[2] : p[0];
          sum += 0.212671f * clean(p[0]) + 0.715160f * clean(g) + 0.072169f * clean(b);
        }
      const float mean = sum / float((y1 - y0) * (x1 - x0));
      if (mean > 1e-8f) {
        logSum += std::log2(mean);
        ++count;
      }
    }
  return count > 0 ? float(0.18 / std::exp2(logSum / count)) : 1.0f;
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
