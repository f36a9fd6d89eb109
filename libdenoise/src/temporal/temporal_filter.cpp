#include "dn/temporal/temporal_filter.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <stdexcept>

namespace dn::temporal {

namespace {

// Reinhard's x / (1 + x) after bringing the frame's mean to 0.18: differences
// then weigh as they show, in dark and bright frames alike.
Image tonemapped(const Image& linear, double scale) {
  Image out = linear;
  for (float& v : out.pixels) {
    const double s = std::max(0.0, double(v) * scale);
    v = static_cast<float>(s / (1.0 + s));
  }
  return out;
}

double exposureScale(const Image& color) {
  double sum = 0.0;
  for (float v : color.pixels) sum += std::max(0.0f, v);
  const double mean = sum / std::max<std::size_t>(1, color.pixels.size());
  return mean > 1e-12 ? 0.18 / mean : 1.0;
}

Image difference(const Image& a, const Image& b) {
  Image out = a;
  for (std::size_t i = 0; i < out.pixels.size(); ++i) out.pixels[i] -= b.pixels[i];
  return out;
}

// Correlation of two residual images over the pixels where `trust` > 0.
double correlation(const Image& a, const Image& b, const Image& trust) {
  double ab = 0.0, aa = 0.0, bb = 0.0;
  for (std::size_t i = 0; i < trust.pixels.size(); ++i) {
    if (trust.pixels[i] <= 0.0f) continue;
    for (int c = 0; c < a.channels; ++c) {
      const double u = a.pixels[i * a.channels + c], v = b.pixels[i * b.channels + c];
      ab += u * v, aa += u * u, bb += v * v;
    }
  }
  return aa > 0.0 && bb > 0.0 ? ab / std::sqrt(aa * bb) : 0.0;
}

// Per pixel, the mean over channels of |a - b|.
std::vector<float> absoluteDifference(const Image& a, const Image& b) {
  std::vector<float> d(a.pixelCount());
  for (std::size_t i = 0; i < d.size(); ++i) {
    double s = 0.0;
    for (int c = 0; c < a.channels; ++c)
      s += std::abs(a.pixels[i * a.channels + c] - b.pixels[i * b.channels + c]);
    d[i] = static_cast<float>(s / a.channels);
  }
  return d;
}

// The spread of the frames' leftover errors from the lower quartile of
// |difference| over trusted pixels (a half-normal's is 0.3186 sigma): robust
// to moving shadows and highlights over up to three quarters of the frame.
double robustSpread(const std::vector<float>& d, const Image& trust) {
  std::vector<float> values;
  for (std::size_t i = 0; i < d.size(); ++i)
    if (trust.pixels[i] > 0.0f) values.push_back(d[i]);
  if (values.empty()) return 0.0;
  auto quartile = values.begin() + values.size() / 4;
  std::nth_element(values.begin(), quartile, values.end());
  return *quartile / 0.3186;
}

// Per pixel, the RMS over a (2r+1)^2 box of the frame's noise residual (mean
// over channels): where the render is noisier, the denoised frames' leftover
// errors, and so their differences, are larger.
std::vector<float> localNoise(const Image& residual, int r) {
  const int w = residual.width, h = residual.height;
  std::vector<double> integral(static_cast<std::size_t>(w + 1) * (h + 1), 0.0);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      double e = 0.0;
      for (int c = 0; c < residual.channels; ++c) e += std::pow(residual.at(x, y, c), 2);
      integral[(y + 1) * (w + 1) + x + 1] = e / residual.channels + integral[y * (w + 1) + x + 1] +
                                            integral[(y + 1) * (w + 1) + x] -
                                            integral[y * (w + 1) + x];
    }
  std::vector<float> out(residual.pixelCount());
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const int x0 = std::max(0, x - r), x1 = std::min(w, x + r + 1);
      const int y0 = std::max(0, y - r), y1 = std::min(h, y + r + 1);
      const double box = integral[y1 * (w + 1) + x1] - integral[y0 * (w + 1) + x1] -
                         integral[y1 * (w + 1) + x0] + integral[y0 * (w + 1) + x0];
      out[y * w + x] = static_cast<float>(std::sqrt(box / ((x1 - x0) * (y1 - y0))));
    }
  return out;
}

// Per pixel, how many standard errors the neighbour's noisy render (brought to
// the nearest pixel, so its noise stays independent) differs from the frame's,
// both averaged over a (2r+1)^2 box of trusted pixels: a change of light that
// the noise cannot explain, at a scale set by the renders alone.
std::vector<float> lightChange(const Image& current, const Image& moved, const Image& trust,
                               const Image& currentResidual, const Image& movedResidual, int r) {
  const int w = current.width, h = current.height, channels = current.channels;
  // Integral images of: count, difference, and the two residuals' squares.
  std::vector<std::array<double, 3>> integral(static_cast<std::size_t>(w + 1) * (h + 1));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      std::array<double, 3> v = {0.0, 0.0, 0.0};
      const std::size_t i = static_cast<std::size_t>(y) * w + x;
      if (trust.pixels[i] > 0.0f) {
        v[0] = 1.0;
        for (int c = 0; c < channels; ++c) {
          v[1] += (moved.pixels[i * channels + c] - current.pixels[i * channels + c]) / channels;
          v[2] += (std::pow(currentResidual.pixels[i * channels + c], 2) +
                   std::pow(movedResidual.pixels[i * channels + c], 2)) /
                  (channels * channels);
        }
      }
      auto& out = integral[(y + 1) * (w + 1) + x + 1];
      const auto& up = integral[y * (w + 1) + x + 1];
      const auto& left = integral[(y + 1) * (w + 1) + x];
      const auto& corner = integral[y * (w + 1) + x];
      for (int k = 0; k < 3; ++k) out[k] = v[k] + up[k] + left[k] - corner[k];
    }
  std::vector<float> z(current.pixelCount(), 0.0f);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const int x0 = std::max(0, x - r), x1 = std::min(w, x + r + 1);
      const int y0 = std::max(0, y - r), y1 = std::min(h, y + r + 1);
      std::array<double, 3> box;
      for (int k = 0; k < 3; ++k)
        box[k] = integral[y1 * (w + 1) + x1][k] - integral[y0 * (w + 1) + x1][k] -
                 integral[y1 * (w + 1) + x0][k] + integral[y0 * (w + 1) + x0][k];
      if (box[0] < 1.0 || box[2] <= 0.0) continue;
      // The mean of n differences has variance sum(var) / n^2.
      z[y * w + x] = static_cast<float>(std::abs(box[1] / box[0]) / (std::sqrt(box[2]) / box[0]));
    }
  return z;
}

motion::FrameGeometry geometryOf(const WindowFrame& frame) {
  return {&frame.guides, &frame.motion};
}

}  // namespace

TemporalResult filterFrame(const std::vector<const WindowFrame*>& window, std::size_t centre,
                           const TemporalOptions& options) {
  if (centre >= window.size() || !window[centre])
    throw std::invalid_argument("filterFrame: the centre frame is missing");
  const WindowFrame& current = *window[centre];
  const Image& base = current.denoised;
  const double scale = exposureScale(base);
  const Image baseMapped = tonemapped(base, scale);
  const Image baseResidual = difference(tonemapped(current.noisy, scale), baseMapped);
  std::vector<float> noiseLevel = localNoise(baseResidual, 3);
  {  // a floor: flat, noise-free regions (a clear sky) must not divide by zero
    std::vector<float> sorted = noiseLevel;
    auto middle = sorted.begin() + sorted.size() / 2;
    std::nth_element(sorted.begin(), middle, sorted.end());
    const float floor = std::max(0.1f * *middle, 1e-4f);
    for (float& v : noiseLevel) v = std::max(v, floor);
  }

  std::vector<double> sum(base.pixels.begin(), base.pixels.end());
  std::vector<double> weight(base.pixelCount(), 1.0);
  TemporalResult result;
  for (int side : {-1, 1}) {
    std::vector<motion::FrameGeometry> chain = {geometryOf(current)};
    for (int k = 1; k <= options.radius; ++k) {
      const long index = static_cast<long>(centre) + side * k;
      if (index < 0 || index >= static_cast<long>(window.size()) || !window[index]) break;
      const WindowFrame& neighbour = *window[index];
      if (neighbour.motion.empty() || current.motion.empty()) break;
      chain.push_back(geometryOf(neighbour));
      ++result.stats.neighbours;
      const Image positions = motion::chainPositions(chain, side > 0, options.trust);
      const motion::Reprojected moved = motion::reproject(neighbour.denoised, neighbour.guides,
                                                          positions, current.guides, options.trust);
      const Image residual = motion::reprojectNearest(
          difference(tonemapped(neighbour.noisy, scale), tonemapped(neighbour.denoised, scale)),
          positions);
      const std::vector<float> changed =
          lightChange(tonemapped(current.noisy, scale),
                      motion::reprojectNearest(tonemapped(neighbour.noisy, scale), positions),
                      moved.trust, baseResidual, residual, options.lightBox);
      if (correlation(baseResidual, residual, moved.trust) > options.repeatedNoiseCorrelation) {
        ++result.stats.repeatedNoise;
        result.stats.trusted.push_back(0.0);
        continue;
      }
      std::vector<float> d = absoluteDifference(tonemapped(moved.image, scale), baseMapped);
      for (std::size_t i = 0; i < d.size(); ++i) d[i] /= noiseLevel[i];
      // Where the light changed over the whole frame (a moving lamp), the
      // differences' own spread is large too: the cap keeps them rejected.
      const double spread = std::min(robustSpread(d, moved.trust), options.maxSpread);
      std::size_t used = 0;
      for (std::size_t i = 0; i < d.size(); ++i) {
        double w = moved.trust.pixels[i];
        if (w <= 0.0) continue;
        if (spread > 0.0) {
          const double z = d[i] / spread;
          w *= std::clamp((options.colourHigh - z) / (options.colourHigh - options.colourLow), 0.0,
                          1.0);
        }
        w *= std::clamp((options.lightHigh - changed[i]) / (options.lightHigh - options.lightLow),
                        0.0, 1.0);
        if (w <= 0.0) continue;
        ++used;
        weight[i] += w;
        for (int c = 0; c < 3; ++c) sum[3 * i + c] += w * moved.image.pixels[3 * i + c];
      }
      result.stats.trusted.push_back(double(used) / d.size());
    }
  }
  result.color = Image(base.width, base.height, 3);
  double share = 0.0;
  for (std::size_t i = 0; i < weight.size(); ++i) {
    for (int c = 0; c < 3; ++c)
      result.color.pixels[3 * i + c] = static_cast<float>(sum[3 * i + c] / weight[i]);
    share += 1.0 - 1.0 / weight[i];
  }
  result.stats.historyShare = share / std::max<std::size_t>(1, weight.size());
  return result;
}

FrameBuffers accumulateInputs(const std::vector<const FrameBuffers*>& inputs,
                              const std::vector<const WindowFrame*>& window, std::size_t centre,
                              const TemporalOptions& options, TemporalStats& stats) {
  if (centre >= window.size() || !window[centre] || !inputs[centre])
    throw std::invalid_argument("accumulateInputs: the centre frame is missing");
  const WindowFrame& current = *window[centre];
  FrameBuffers out = *inputs[centre];
  std::map<std::string, std::vector<double>> sums;
  for (const auto& [name, image] : out.buffers)
    if (name != "depth") sums[name].assign(image.pixels.begin(), image.pixels.end());
  std::vector<double> weight(out.width * static_cast<std::size_t>(out.height), 1.0);
  motion::TrustOptions trust = options.trust;
  trust.nearest = true;
  stats = TemporalStats{};
  for (int side : {-1, 1}) {
    std::vector<motion::FrameGeometry> chain = {geometryOf(current)};
    for (int k = 1; k <= options.radius; ++k) {
      const long index = static_cast<long>(centre) + side * k;
      if (index < 0 || index >= static_cast<long>(window.size()) || !window[index] ||
          !inputs[index])
        break;
      const WindowFrame& neighbour = *window[index];
      if (neighbour.motion.empty() || current.motion.empty()) break;
      const bool sameBuffers = std::all_of(sums.begin(), sums.end(), [&](const auto& entry) {
        return inputs[index]->has(entry.first) &&
               inputs[index]->get(entry.first).sameShape(out.get(entry.first));
      });
      if (!sameBuffers) break;
      chain.push_back(geometryOf(neighbour));
      ++stats.neighbours;
      const Image positions = motion::chainPositions(chain, side > 0, trust);
      Image trusted;
      for (auto& [name, sum] : sums) {
        const motion::Reprojected moved = motion::reproject(
            inputs[index]->get(name), neighbour.guides, positions, current.guides, trust);
        const int channels = moved.image.channels;
        for (std::size_t i = 0; i < weight.size(); ++i)
          for (int c = 0; c < channels; ++c)
            sum[i * channels + c] += moved.trust.pixels[i] * moved.image.pixels[i * channels + c];
        if (trusted.empty()) trusted = moved.trust;
      }
      std::size_t used = 0;
      for (std::size_t i = 0; i < weight.size(); ++i)
        weight[i] += trusted.pixels[i], used += trusted.pixels[i] > 0.0f;
      stats.trusted.push_back(double(used) / weight.size());
    }
  }
  double share = 0.0;
  for (auto& [name, sum] : sums) {
    Image& image = out.buffers[name];
    for (std::size_t i = 0; i < weight.size(); ++i)
      for (int c = 0; c < image.channels; ++c)
        image.pixels[i * image.channels + c] =
            static_cast<float>(sum[i * image.channels + c] / weight[i]);
  }
  for (double w : weight) share += 1.0 - 1.0 / w;
  stats.historyShare = share / std::max<std::size_t>(1, weight.size());
  return out;
}

}  // namespace dn::temporal
