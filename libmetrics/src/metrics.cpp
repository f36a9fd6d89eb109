#include "dn/metrics.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "dn/flip.h"
#include "dn/parallel.h"
#include "dn/tonemap.h"

namespace dn::metrics {

namespace {

void requireComparable(const Image& reference, const Image& test) {
  if (reference.width != test.width || reference.height != test.height)
    throw std::invalid_argument("image sizes differ: " + std::to_string(reference.width) + "x" +
                                std::to_string(reference.height) + " vs " +
                                std::to_string(test.width) + "x" + std::to_string(test.height));
  if (reference.channels < 3 || test.channels < 3)
    throw std::invalid_argument("metrics need at least 3 channels");
}

float clampHdr(float v) { return std::clamp(v, 0.0f, tonemap::kHdrMax); }

// Sums f(ref, test) over the RGB channels of every pixel, in parallel, in double.
template <class F>
double sumRgb(const Image& reference, const Image& test, F&& f) {
  std::vector<double> rowSums(reference.height, 0.0);
  parallelFor(reference.height, [&](int y0, int y1) {
    for (int y = y0; y < y1; ++y) {
      double sum = 0.0;
      for (int x = 0; x < reference.width; ++x) {
        const float* r = reference.pixel(x, y);
        const float* t = test.pixel(x, y);
        for (int c = 0; c < 3; ++c) sum += f(r[c], t[c]);
      }
      rowSums[y] = sum;
    }
  });
  double total = 0.0;
  for (double s : rowSums) total += s;
  return total;
}

template <class F>
double meanRgb(const Image& reference, const Image& test, F&& f) {
  requireComparable(reference, test);
  return sumRgb(reference, test, f) / (3.0 * reference.pixelCount());
}

// One channel of an image, Reinhard-tonemapped, as a dense plane.
std::vector<float> reinhardPlane(const Image& image, int channel) {
  std::vector<float> plane(image.pixelCount());
  for (std::size_t i = 0; i < plane.size(); ++i)
    plane[i] = std::min(tonemap::reinhard(image.pixels[i * image.channels + channel]), 1.0f);
  return plane;
}

// "Valid" separable Gaussian filter: output is (w - k + 1) x (h - k + 1).
std::vector<float> gaussianValid(const std::vector<float>& in, int w, int h,
                                 const std::vector<float>& kernel) {
  const int k = static_cast<int>(kernel.size());
  const int ow = w - k + 1, oh = h - k + 1;
  std::vector<float> horizontal(static_cast<std::size_t>(ow) * h),
      out(static_cast<std::size_t>(ow) * oh);
  parallelFor(h, [&](int y0, int y1) {
    for (int y = y0; y < y1; ++y)
      for (int x = 0; x < ow; ++x) {
        float s = 0.0f;
        for (int i = 0; i < k; ++i) s += kernel[i] * in[static_cast<std::size_t>(y) * w + x + i];
        horizontal[static_cast<std::size_t>(y) * ow + x] = s;
      }
  });
  parallelFor(oh, [&](int y0, int y1) {
    for (int y = y0; y < y1; ++y)
      for (int x = 0; x < ow; ++x) {
        float s = 0.0f;
        for (int i = 0; i < k; ++i)
          s += kernel[i] * horizontal[static_cast<std::size_t>(y + i) * ow + x];
        out[static_cast<std::size_t>(y) * ow + x] = s;
      }
  });
  return out;
}

std::vector<float> ssimKernel() {
  constexpr int kSize = 11;
  constexpr double kSigma = 1.5;
  std::vector<float> kernel(kSize);
  double sum = 0.0;
  for (int i = 0; i < kSize; ++i) {
    double d = i - kSize / 2;
    sum += kernel[i] = static_cast<float>(std::exp(-d * d / (2 * kSigma * kSigma)));
  }
  for (float& v : kernel) v = static_cast<float>(v / sum);
  return kernel;
}

double ssimChannel(const std::vector<float>& x, const std::vector<float>& y, int w, int h) {
  constexpr double c1 = 0.01 * 0.01, c2 = 0.03 * 0.03;  // (K L)^2 with L = 1
  const auto kernel = ssimKernel();
  std::vector<float> xx(x.size()), yy(x.size()), xy(x.size());
  for (std::size_t i = 0; i < x.size(); ++i)
    xx[i] = x[i] * x[i], yy[i] = y[i] * y[i], xy[i] = x[i] * y[i];
  auto mx = gaussianValid(x, w, h, kernel), my = gaussianValid(y, w, h, kernel);
  auto sxx = gaussianValid(xx, w, h, kernel), syy = gaussianValid(yy, w, h, kernel),
       sxy = gaussianValid(xy, w, h, kernel);
  double sum = 0.0;
  for (std::size_t i = 0; i < mx.size(); ++i) {
    double ux = mx[i], uy = my[i];
    double vx = sxx[i] - ux * ux, vy = syy[i] - uy * uy, cov = sxy[i] - ux * uy;
    sum += ((2 * ux * uy + c1) * (2 * cov + c2)) / ((ux * ux + uy * uy + c1) * (vx + vy + c2));
  }
  return sum / mx.size();
}

}  // namespace

double l1(const Image& reference, const Image& test) {
  return meanRgb(reference, test,
                 [](float r, float t) { return std::abs(clampHdr(r) - clampHdr(t)); });
}

double mse(const Image& reference, const Image& test) {
  return meanRgb(reference, test, [](float r, float t) {
    double d = clampHdr(r) - clampHdr(t);
    return d * d;
  });
}

double relMse(const Image& reference, const Image& test) {
  return meanRgb(reference, test, [](float r, float t) {
    double rr = std::max(r, 0.0f), d = rr - std::max(t, 0.0f);
    return d * d / (rr * rr + kRelMseEpsilon);
  });
}

double psnr(const Image& reference, const Image& test) {
  double m = meanRgb(reference, test, [](float r, float t) {
    double d = std::min(tonemap::reinhard(r), 1.0f) - std::min(tonemap::reinhard(t), 1.0f);
    return d * d;
  });
  return m > 0.0 ? 10.0 * std::log10(1.0 / m) : INFINITY;
}

double flicker(const Image& previousReference, const Image& previousTest, const Image& reference,
               const Image& test) {
  requireComparable(reference, test);
  requireComparable(previousReference, previousTest);
  requireComparable(reference, previousReference);
  auto mapped = [](float v) { return double(std::min(tonemap::reinhard(v), 1.0f)); };
  double sum = 0.0;
  for (std::size_t i = 0; i < reference.pixelCount(); ++i)
    for (int c = 0; c < 3; ++c) {
      const std::size_t now = i * reference.channels + c,
                        before = i * previousReference.channels + c;
      const double e = mapped(test.pixels[i * test.channels + c]) - mapped(reference.pixels[now]);
      const double ePrevious = mapped(previousTest.pixels[i * previousTest.channels + c]) -
                               mapped(previousReference.pixels[before]);
      sum += std::abs(e - ePrevious);
    }
  return sum / (3.0 * reference.pixelCount());
}

double ssim(const Image& reference, const Image& test) {
  requireComparable(reference, test);
  if (reference.width < 11 || reference.height < 11)
    throw std::invalid_argument("SSIM needs images of at least 11x11 pixels");
  double sum = 0.0;
  for (int c = 0; c < 3; ++c)
    sum += ssimChannel(reinhardPlane(reference, c), reinhardPlane(test, c), reference.width,
                       reference.height);
  return sum / 3.0;
}

double smape(const Image& reference, const Image& test) {
  requireComparable(reference, test);
  const double n = 3.0 * reference.pixelCount();  // norms as means: eps means the same at any size
  double diff =
      sumRgb(reference, test, [](float r, float t) { return std::abs(clampHdr(r) - clampHdr(t)); });
  double norms =
      sumRgb(reference, test, [](float r, float t) { return clampHdr(r) + clampHdr(t); });
  return (diff / n) / (norms / n + kSmapeEpsilon);
}

Image reinhardSrgb(const Image& linear) {
  Image out(linear.width, linear.height, 3);
  for (std::size_t i = 0; i < linear.pixelCount(); ++i)
    for (int c = 0; c < 3; ++c)
      out.pixels[i * 3 + c] = std::min(
          tonemap::srgbEncode(tonemap::reinhard(linear.pixels[i * linear.channels + c])), 1.0f);
  return out;
}

const std::vector<std::string>& metricNames() {
  static const std::vector<std::string> names = {"l1",   "mse",   "relmse", "psnr",
                                                 "ssim", "smape", "flip",   "hdrflip"};
  return names;
}

bool isMetricName(const std::string& name) {
  const auto& names = metricNames();
  return std::find(names.begin(), names.end(), name) != names.end();
}

bool higherIsBetter(const std::string& name) { return name == "psnr" || name == "ssim"; }

Comparison compare(const Image& reference, const Image& test,
                   const std::vector<std::string>& names) {
  requireComparable(reference, test);
  Comparison result;
  for (const auto& name : names) {
    double value = 0.0;
    if (name == "l1")
      value = l1(reference, test);
    else if (name == "mse")
      value = mse(reference, test);
    else if (name == "relmse")
      value = relMse(reference, test);
    else if (name == "psnr")
      value = psnr(reference, test);
    else if (name == "ssim")
      value = ssim(reference, test);
    else if (name == "smape")
      value = smape(reference, test);
    else if (name == "flip") {
      result.flipMap = flip::ldrErrorMap(reinhardSrgb(reference), reinhardSrgb(test));
      value = flip::statistics(result.flipMap).mean;
    } else if (name == "hdrflip") {
      result.hdrFlipMap = flip::hdrErrorMap(reference, test);
      value = flip::statistics(result.hdrFlipMap).mean;
    } else {
      throw std::invalid_argument("unknown metric '" + name + "'");
    }
    result.values[name] = value;
  }
  return result;
}

}  // namespace dn::metrics
