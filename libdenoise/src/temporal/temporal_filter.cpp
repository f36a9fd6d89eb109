#include "dn/temporal/temporal_filter.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <functional>
#include <numeric>
#include <optional>
#include <stdexcept>

#include "dn/temporal/parallel.h"
#include "dn/tonemap.h"

namespace dn::temporal {

namespace {

// Reinhard's x / (1 + x) after `scale`, OIDN's autoexposure of the frame's
// result: differences then weigh as they show, in dark and bright frames alike.
// (Not the mean: a visible sun can hold most of a frame's mean, and darken
// everything else to nothing.)
float tonemappedValue(float v, double scale) {
  const double s = std::max(0.0, double(v) * scale);           // NaN: 0
  return s < 1e30 ? static_cast<float>(s / (1.0 + s)) : 1.0f;  // an infinite firefly: 1
}

Image tonemapped(const Image& linear, double scale) {
  Image out(linear.width, linear.height, linear.channels);
  std::transform(linear.pixels.begin(), linear.pixels.end(), out.pixels.begin(),
                 [scale](float v) { return tonemappedValue(v, scale); });
  return out;
}

// A test's weight: 1 up to `low`, falling linearly to 0 at `high`.
double fallingWeight(double value, double low, double high) {
  return std::clamp((high - value) / (high - low), 0.0, 1.0);
}

// Window frame k's image, nullptr where it has none.
const Image* imageAt(const std::vector<const Image*>& images, std::size_t k) {
  return k < images.size() ? images[k] : nullptr;
}

Image difference(const Image& a, const Image& b) {
  Image out(a.width, a.height, a.channels);
  std::transform(a.pixels.begin(), a.pixels.end(), b.pixels.begin(), out.pixels.begin(),
                 std::minus<float>());
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

// Per pixel, the mean over channels of |f(a) - b|.
template <class Map>
std::vector<float> absoluteDifference(const Image& a, const Image& b, Map f) {
  std::vector<float> d(a.pixelCount());
  for (std::size_t i = 0; i < d.size(); ++i) {
    double s = 0.0;
    for (int c = 0; c < a.channels; ++c)
      s += std::abs(f(a.pixels[i * a.channels + c]) - b.pixels[i * b.channels + c]);
    d[i] = static_cast<float>(s / a.channels);
  }
  return d;
}

std::vector<float> absoluteDifference(const Image& a, const Image& b) {
  return absoluteDifference(a, b, [](float v) { return v; });
}

// absoluteDifference(tonemapped(linear, scale), mapped), without the tonemapped image.
std::vector<float> mappedDifference(const Image& linear, double scale, const Image& mapped) {
  return absoluteDifference(linear, mapped, [scale](float v) { return tonemappedValue(v, scale); });
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

// Sums of per-pixel values over boxes of (2r+1)^2 pixels, clipped to the
// image, from integral images: `values(i, v)` writes pixel i's `count`
// values. The integral's rows are made as the boxes move down and only the
// 2r+2 a box spans are kept (7 MB for a 63x63 box of 7 values at 1080p, not
// 124 MB), so boxes are asked for row after row, never going back up.
template <class Values>
class BoxSums {
 public:
  BoxSums(int width, int height, int count, int r, Values values)
      : width_(width),
        height_(height),
        count_(count),
        r_(r),
        rows_(std::min(2 * r + 2, height + 1)),
        values_(std::move(values)),
        integral_(static_cast<std::size_t>(rows_) * (width + 1) * count, 0.0),
        v_(count) {}

  // The box around (x, y) and its pixel count, clipped; `top` and `bottom`
  // point at its corners' integral values in the rows kept.
  struct Box {
    int x0, y0, x1, y1;
    const double *top0, *top1, *bottom0, *bottom1;  // at (x0, y0), (x1, y0), (x0, y1), (x1, y1)
    int pixels() const { return (x1 - x0) * (y1 - y0); }
  };
  Box box(int x, int y) {
    const int x0 = std::max(0, x - r_), y0 = std::max(0, y - r_);
    const int x1 = std::min(width_, x + r_ + 1), y1 = std::min(height_, y + r_ + 1);
    while (made_ < y1) makeRow();
    const double *top = row(y0), *bottom = row(y1);
    return {x0,
            y0,
            x1,
            y1,
            top + x0 * count_,
            top + x1 * count_,
            bottom + x0 * count_,
            bottom + x1 * count_};
  }

  double sum(const Box& b, int k) const {
    return b.bottom1[k] - b.top1[k] - b.bottom0[k] + b.top0[k];
  }

 private:
  // Integral row made_ + 1 from the image's row made_ (row 0 is zeros, and
  // so is every row's first column).
  void makeRow() {
    const int y = made_++;
    const double* above = row(y);
    double* made = row(y + 1);
    // v_ is all zeros before each pixel (a values_ that takes nothing there
    // writes none): cleared as it is read, without a call a pixel.
    for (int x = 0; x < width_; ++x) {
      values_(static_cast<std::size_t>(y) * width_ + x, v_.data());
      for (int k = 0; k < count_; ++k) {
        made[(x + 1) * count_ + k] =
            v_[k] + above[(x + 1) * count_ + k] + made[x * count_ + k] - above[x * count_ + k];
        v_[k] = 0.0;
      }
    }
  }
  // Integral row y (of the 2r+2 kept) and its values, column after column.
  double* row(int y) {
    return &integral_[static_cast<std::size_t>(y % rows_) * (width_ + 1) * count_];
  }

  int width_, height_, count_, r_, rows_;
  int made_ = 0;  // integral rows made after row 0
  Values values_;
  std::vector<double> integral_;
  std::vector<double> v_;
};

// Per pixel, the RMS over a (2r+1)^2 box of the frame's noise residual (mean
// over channels): where the render is noisier, the denoised frames' leftover
// errors, and so their differences, are larger.
std::vector<float> localNoise(const Image& residual, int r) {
  const int w = residual.width, h = residual.height, channels = residual.channels;
  BoxSums sums(w, h, 1, r, [&](std::size_t i, double* v) {
    double e = 0.0;
    for (int c = 0; c < channels; ++c) e += std::pow(residual.pixels[i * channels + c], 2);
    v[0] = e / channels;
  });
  std::vector<float> out(residual.pixelCount());
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const auto box = sums.box(x, y);
      out[y * w + x] = static_cast<float>(std::sqrt(sums.sum(box, 0) / box.pixels()));
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
  // Over trusted pixels: count, difference, and the two residuals' squares.
  BoxSums sums(w, h, 3, r, [&](std::size_t i, double* v) {
    if (trust.pixels[i] <= 0.0f) return;
    v[0] = 1.0;
    for (int c = 0; c < channels; ++c) {
      v[1] += (moved.pixels[i * channels + c] - current.pixels[i * channels + c]) / channels;
      v[2] += (std::pow(currentResidual.pixels[i * channels + c], 2) +
               std::pow(movedResidual.pixels[i * channels + c], 2)) /
              (channels * channels);
    }
  });
  std::vector<float> z(current.pixelCount(), 0.0f);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const auto box = sums.box(x, y);
      const double n = sums.sum(box, 0), difference = sums.sum(box, 1), variance = sums.sum(box, 2);
      if (n < 1.0 || variance <= 0.0) continue;
      // The mean of n differences has variance sum(var) / n^2.
      z[y * w + x] = static_cast<float>(std::abs(difference / n) / (std::sqrt(variance) / n));
    }
  return z;
}

// The mean of `values` over the pixels where `trust` > 0 (0 where none is).
double trustedMean(const std::vector<float>& values, const Image& trust) {
  double sum = 0.0;
  std::size_t count = 0;
  for (std::size_t i = 0; i < values.size(); ++i)
    if (trust.pixels[i] > 0.0f) sum += values[i], ++count;
  return count ? sum / count : 0.0;
}

// Per pixel and channel, the mean of `image` over the (2r+1)^2 box of pixels
// where `trust` > 0; -1 where the box holds none.
Image trustedBoxMean(const Image& image, const Image& trust, int r) {
  const int w = image.width, h = image.height, channels = image.channels;
  // Over trusted pixels: the values, then the count.
  BoxSums sums(w, h, channels + 1, r, [&](std::size_t i, double* v) {
    if (trust.pixels[i] <= 0.0f) return;
    for (int c = 0; c < channels; ++c) v[c] = image.pixels[i * channels + c];
    v[channels] = 1.0;
  });
  Image out(w, h, channels);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const auto box = sums.box(x, y);
      const double count = sums.sum(box, channels);
      for (int c = 0; c < channels; ++c)
        out.at(x, y, c) = count > 0.0 ? static_cast<float>(sums.sum(box, c) / count) : -1.0f;
    }
  return out;
}

// The factor that brings a neighbour's result to the frame's light: per pixel
// and channel, the ratio of the frame's and the neighbour's results, each
// averaged over the (2r+1)^2 box of trusted pixels around (1 where undefined).
// What the neighbour adds is then its detail within the box, whose leftover
// error differs from the frame's. Where the boxes' light differs by more than
// `range` times either way (a lamp's pool arrived or left), no factor brings
// that detail to the frame's light: 0 in every channel, and the pixel is not
// taken (relitWeight).
Image relightFactor(const Image& moved, const Image& own, const Image& trust, int r, double range) {
  const Image ownMean = trustedBoxMean(own, trust, r), movedMean = trustedBoxMean(moved, trust, r);
  const int channels = moved.channels;
  Image factor(moved.width, moved.height, channels, 1.0f);
  const float low = static_cast<float>(1.0 / range), high = static_cast<float>(range);
  for (std::size_t i = 0; i < factor.pixelCount(); ++i) {
    const float* a = &ownMean.pixels[i * channels];
    const float* b = &movedMean.pixels[i * channels];
    if (a[0] < 0.0f) continue;  // no trusted pixel in the box
    double ownLight = 0.0, movedLight = 0.0;
    for (int c = 0; c < channels; ++c) ownLight += a[c], movedLight += b[c];
    float* f = &factor.pixels[i * channels];
    if (ownLight > range * movedLight || movedLight > range * ownLight) {
      std::fill_n(f, channels, 0.0f);
      continue;
    }
    for (int c = 0; c < channels; ++c)
      if (b[c] > 1e-6f) f[c] = std::clamp(a[c] / b[c], low, high);
  }
  return factor;
}

// Whether relightFactor gave pixel i of `factor` a ratio (else it is not taken).
bool relitTaken(const Image& factor, std::size_t i) {
  return factor.pixels[i * factor.channels] != 0.0f;
}

// `weight` left where relightFactor gave `factor` a ratio, 0 where it did not.
std::vector<double> relitWeight(std::vector<double> weight, const Image& factor) {
  for (std::size_t i = 0; i < weight.size(); ++i)
    if (!relitTaken(factor, i)) weight[i] = 0.0;
  return weight;
}

// The factor that brings a neighbour's image to the frame's light where its
// light drifted: per pixel and channel, the ratio of the frame's and the
// neighbour's images, each averaged over the (2r+1)^2 box of the pixels
// `weight` takes (clamped to [1/2, 2]), where the boxes' light (the channels
// summed) differs by more than `threshold` relative, or, given `where`, at
// its pixels (the colour's decision, for its light passes); 1 elsewhere.
Image driftFactor(const Image& moved, const Image& own, const std::vector<double>& weight, int r,
                  double threshold, const std::vector<unsigned char>* where = nullptr) {
  const int w = own.width, h = own.height, channels = own.channels;
  // Over the pixels taken: the frame's values, the neighbour's, then the count.
  BoxSums sums(w, h, 2 * channels + 1, r, [&](std::size_t i, double* v) {
    if (weight[i] <= 0.0) return;
    for (int c = 0; c < channels; ++c)
      v[c] = own.pixels[i * channels + c], v[channels + c] = moved.pixels[i * channels + c];
    v[2 * channels] = 1.0;
  });
  Image factor(w, h, channels, 1.0f);
  std::vector<float> a(channels), b(channels);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      if (where && !(*where)[static_cast<std::size_t>(y) * w + x]) continue;
      const auto box = sums.box(x, y);
      const double count = sums.sum(box, 2 * channels);
      if (count <= 0.0) continue;  // nothing taken in the box
      double ownLight = 0.0, movedLight = 0.0;
      for (int c = 0; c < channels; ++c) {
        a[c] = static_cast<float>(sums.sum(box, c) / count);
        b[c] = static_cast<float>(sums.sum(box, channels + c) / count);
        ownLight += a[c], movedLight += b[c];
      }
      if (!where && (!(movedLight > 0.0) || std::abs(ownLight / movedLight - 1.0) <= threshold))
        continue;
      float* f = factor.pixel(x, y);
      for (int c = 0; c < channels; ++c)
        if (b[c] > 1e-6f) f[c] = std::clamp(a[c] / b[c], 0.5f, 2.0f);
    }
  return factor;
}

// Per pixel, 1 where `factor` changes any channel.
std::vector<unsigned char> changedPixels(const Image& factor) {
  std::vector<unsigned char> out(factor.pixelCount(), 0);
  for (std::size_t i = 0; i < out.size(); ++i)
    for (int c = 0; c < factor.channels; ++c)
      if (factor.pixels[i * factor.channels + c] != 1.0f) out[i] = 1;
  return out;
}

// Per pixel, how still its surface stood on screen between the frame and the
// neighbour at `positions`: 1 where it did not move, falling to 0 at `pixels`.
Image stillness(const Image& positions, double pixels) {
  Image out(positions.width, positions.height, 1);
  for (int y = 0; y < positions.height; ++y)
    for (int x = 0; x < positions.width; ++x) {
      const float* p = positions.pixel(x, y);
      const double moved = std::hypot(p[0] - x, p[1] - y);  // NaN: left the screen
      out.at(x, y, 0) = moved < pixels ? static_cast<float>(1.0 - moved / pixels) : 0.0f;
    }
  return out;
}

Image scaled(Image image, const Image& factor) {
  for (std::size_t i = 0; i < image.pixels.size(); ++i) image.pixels[i] *= factor.pixels[i];
  return image;
}

// A neighbour's noisy render, tonemapped, and its noise as the denoiser saw it
// (the render less its result, both tonemapped), each brought into the frame
// at the nearest pixel, so that its noise stays independent; zeros where lost.
struct NearestRender {
  Image mapped;
  Image residual;
};

NearestRender nearestRender(const Image& noisy, const Image& denoised, const Image& positions,
                            double scale) {
  const int channels = noisy.channels;
  NearestRender out{Image(positions.width, positions.height, channels),
                    Image(positions.width, positions.height, channels)};
  const std::vector<std::int32_t> from =
      motion::nearestPixels(positions, noisy.width, noisy.height);
  for (std::size_t i = 0; i < from.size(); ++i) {
    if (from[i] < 0) continue;
    for (int c = 0; c < channels; ++c) {
      const std::size_t s = std::size_t(from[i]) * channels + c, d = i * channels + c;
      out.mapped.pixels[d] = tonemappedValue(noisy.pixels[s], scale);
      out.residual.pixels[d] = out.mapped.pixels[d] - tonemappedValue(denoised.pixels[s], scale);
    }
  }
  return out;
}

// What the centre frame holds for the tests, computed once per frame.
struct Centre {
  explicit Centre(const WindowFrame& frame);
  Centre(const Centre&) = delete;  // `guides` may point into `unpacked`
  Centre& operator=(const Centre&) = delete;
  // Once the tests are done only the result, the scale and the noise level
  // are needed: about 0.1 GB of a 1080p frame less.
  void dropTestImages() {
    unpacked = motion::Guides();
    guides = motion::GuideImages();
    mapped = noisyMapped = residual = Image();
  }

  Image denoised;              // its result
  motion::Guides unpacked;     // its guides held in half floats, in floats
  motion::GuideImages guides;  // its albedo, normal and depth
  double scale;                // its autoexposure
  Image mapped;                // its result, tonemapped
  Image noisyMapped;           // its render, tonemapped
  Image residual;              // noisyMapped - mapped: its noise, as the denoiser saw it
  std::vector<float> noise;    // the local level of that noise
};

Centre::Centre(const WindowFrame& frame)
    : denoised(frame.denoised.toImage()),
      guides(frame.guides.view(unpacked)),
      scale(tonemap::oidnExposure(denoised)),
      mapped(tonemapped(denoised, scale)) {
  Image scratch;
  noisyMapped = tonemapped(frame.noisy.floats(scratch), scale);
  residual = difference(noisyMapped, mapped);
  noise = localNoise(residual, 3);
  // A floor: flat, noise-free regions (a clear sky) must not divide by zero.
  std::vector<float> sorted = noise;
  auto middle = sorted.begin() + sorted.size() / 2;
  std::nth_element(sorted.begin(), middle, sorted.end());
  const float floor = std::max(0.1f * *middle, 1e-4f);
  for (float& v : noise) v = std::max(v, floor);
}

// One neighbour's result brought into the centre frame, with a weight per
// pixel from the surface and light tests (the colour test comes later, once
// every neighbour is in); or why it was left out whole.
struct Contribution {
  enum class Verdict { Used, Relit, RepeatedNoise, ChangedLight } verdict = Verdict::Used;
  Image image;
  Image history;        // a past neighbour's denoised history, brought in as `image`
  Image historyWeight;  // its weight per pixel relative to `image`'s: stillness
  // Where each pixel of the frame is in the neighbour, and the taps its images are brought in by.
  motion::Resampling resampling;
  // Relit or drifted: the factor its result was brought to the frame's light by.
  Image relight;
  std::vector<unsigned char> drifted;  // drifted: where that factor changed it; else empty
  // The renders' test per pixel (standard errors), for the learned trust; else empty.
  std::vector<float> lightChange;
  std::vector<double> weight;
  double spread = 0.0;      // of its differences from the frame's result, in local noise levels
  double fullSpread = 0.0;  // the same, not capped at maxSpread
};

// Per pixel, |tonemapped `image` - the frame's result|, in local noise levels.
std::vector<float> normalisedDifference(const Centre& centre, const Image& image) {
  std::vector<float> d = mappedDifference(image, centre.scale, centre.mapped);
  for (std::size_t i = 0; i < d.size(); ++i) d[i] /= centre.noise[i];
  return d;
}

// `positions`: where each pixel of the centre is in the neighbour (motion::chainPositions).
Contribution contributionOf(const Centre& centre, const WindowFrame& neighbour, Image positions,
                            bool forward, const TemporalOptions& options) {
  Contribution out;
  // Only the past carries a denoised history: frames are made in order, and
  // a frame's result must not depend on how far its successors have got.
  Image still;
  if (!forward && !neighbour.history.empty()) still = stillness(positions, options.historyMotion);
  const bool withHistory =
      std::any_of(still.pixels.begin(), still.pixels.end(), [](float w) { return w > 0.0f; });
  motion::Resampling plan = [&] {
    motion::Guides unpacked;  // those held in half floats, while planned
    return motion::planResampling(neighbour.guides.view(unpacked), std::move(positions),
                                  centre.guides, options.trust);
  }();
  Image denoisedScratch, noisyScratch;
  const Image& denoised = neighbour.denoised.floats(denoisedScratch);
  Image moved;
  if (withHistory) {
    // Resampled together: the same taps, cubic where neither overshoots.
    Image historyScratch;
    std::vector<Image> both =
        motion::resample(plan, {&denoised, &neighbour.history.floats(historyScratch)});
    moved = std::move(both[0]);
    out.history = std::move(both[1]);
    out.historyWeight = std::move(still);
  } else {
    moved = motion::resample(plan, denoised);
  }
  const Image& trust = plan.trust;
  const NearestRender render =
      nearestRender(neighbour.noisy.floats(noisyScratch), denoised, plan.positions, centre.scale);
  if (correlation(centre.residual, render.residual, trust) > options.repeatedNoiseCorrelation) {
    out.verdict = Contribution::Verdict::RepeatedNoise;
    return out;
  }
  out.image = std::move(moved);
  std::vector<float> light = lightChange(centre.noisyMapped, render.mapped, trust, centre.residual,
                                         render.residual, options.lightBox);
  double fullSpread = robustSpread(normalisedDifference(centre, out.image), trust);
  Image relitTrust;  // relit: where its factor is defined
  // Where the light changed over most of the frame (a moving lamp, the sun),
  // shading changes too faint for the per-pixel tests are everywhere: the
  // differences' spread is large, or the renders' light test is high on
  // average. Such a neighbour is brought to the frame's light first, and left
  // out whole if that does not bring its spread down. Below that, the cap
  // keeps moving shadows rejected.
  if (fullSpread > options.changedLightSpread ||
      trustedMean(light, trust) > options.changedLightMean) {
    out.relight =
        relightFactor(out.image, centre.denoised, trust, options.relightBox, options.relightRange);
    out.image = scaled(std::move(out.image), out.relight);
    if (!out.history.empty()) out.history = scaled(std::move(out.history), out.relight);
    relitTrust = trust;
    for (std::size_t i = 0; i < relitTrust.pixels.size(); ++i)
      if (!relitTaken(out.relight, i)) relitTrust.pixels[i] = 0.0f;
    fullSpread = robustSpread(normalisedDifference(centre, out.image), relitTrust);
    if (fullSpread > options.changedLightSpread) {
      out.verdict = Contribution::Verdict::ChangedLight;
      return out;
    }
    out.verdict = Contribution::Verdict::Relit;
  }
  out.fullSpread = fullSpread;
  out.spread = std::min(fullSpread, options.maxSpread);
  out.weight.assign(out.image.pixelCount(), 0.0);
  // The renders' own light test would see the change that relighting undid.
  if (!out.relight.empty()) {
    std::copy(relitTrust.pixels.begin(), relitTrust.pixels.end(), out.weight.begin());
    out.resampling = std::move(plan);
    return out;
  }
  for (std::size_t i = 0; i < out.weight.size(); ++i)
    out.weight[i] = trust.pixels[i] * fallingWeight(light[i], options.lightLow, options.lightHigh);
  if (options.learnedTrust || options.observeTrust)
    out.lightChange = std::move(light);  // a feature
  out.resampling = std::move(plan);
  return out;
}

// The frame's result (weight 1) and its neighbours' results, weighted per
// pixel, summed in the neighbours' order (so the result does not depend on
// threads): the mean per channel, and each pixel's total weight.
struct WeightedMean {
  std::vector<double> value;
  std::vector<double> weight;
};

// A neighbour's image brought into the frame and its weights per pixel.
struct Weighted {
  const Image* image;
  const std::vector<double>* weight;
};

// On `threads` threads over bands of pixels, each pixel summed in the same order.
WeightedMean weightedMean(const Image& own, const std::vector<Weighted>& others, int threads = 1) {
  const int channels = own.channels;
  WeightedMean out{{own.pixels.begin(), own.pixels.end()},
                   std::vector<double>(own.pixelCount(), 1.0)};
  forBands(own.pixelCount(), threads, [&](std::size_t begin, std::size_t end) {
    for (const Weighted& k : others) {
      const std::vector<double>& weight = *k.weight;  // empty: left out whole
      const std::size_t stop = std::min(end, weight.size());
      for (std::size_t i = begin; i < stop; ++i) {
        if (weight[i] <= 0.0) continue;
        out.weight[i] += weight[i];
        for (int ch = 0; ch < channels; ++ch)
          out.value[channels * i + ch] += weight[i] * k.image->pixels[channels * i + ch];
      }
    }
    for (std::size_t i = begin * channels; i < end * channels; ++i)
      out.value[i] /= out.weight[i / channels];
  });
  return out;
}

WeightedMean weightedMean(const Image& own, const std::vector<Contribution>& contributions,
                          int threads) {
  std::vector<Weighted> others;
  for (const Contribution& k : contributions) others.push_back({&k.image, &k.weight});
  return weightedMean(own, others, threads);
}

Image toImage(const std::vector<double>& values, const Image& shape) {
  Image out(shape.width, shape.height, shape.channels);
  std::transform(values.begin(), values.end(), out.pixels.begin(),
                 [](double v) { return static_cast<float>(v); });
  return out;
}

// What the colour test compares each neighbour with: the frame's result
// blended with the mean of the frame and every neighbour the other tests kept.
Image colourReference(const Image& own, const std::vector<Contribution>& contributions,
                      double blend, int threads) {
  const std::vector<double> mean = weightedMean(own, contributions, threads).value;
  Image out = own;
  for (std::size_t i = 0; i < out.pixels.size(); ++i)
    out.pixels[i] = static_cast<float>((1.0 - blend) * own.pixels[i] + blend * mean[i]);
  return out;
}

// The colour test: a neighbour's weight falls where its result differs from
// the reference by more than its differences' spread allows (a moving
// highlight, a reflection, a misaligned edge).
void applyColourTest(Contribution& k, const Image& referenceMapped, const Centre& centre,
                     const TemporalOptions& options) {
  if (k.spread <= 0.0) return;
  const std::vector<float> d = mappedDifference(k.image, centre.scale, referenceMapped);
  for (std::size_t i = 0; i < d.size(); ++i) {
    if (k.weight[i] <= 0.0) continue;
    const double z = d[i] / centre.noise[i] / k.spread;
    k.weight[i] *= fallingWeight(z, options.colourLow, options.colourHigh);
  }
}

// The frame's result and every kept neighbour's, weighted by the guides'
// trust alone, tonemapped: what the learned trust compares each with.
Image guideMean(const Centre& centre, const std::vector<Contribution>& contributions, int threads) {
  std::vector<std::vector<double>> trust;
  std::vector<Weighted> others;
  trust.reserve(contributions.size());
  for (const Contribution& k : contributions) {
    if (k.weight.empty()) continue;
    const Image& t = k.resampling.trust;
    trust.emplace_back(t.pixels.begin(), t.pixels.end());
    others.push_back({&k.image, &trust.back()});
  }
  const Image& own = centre.denoised;
  return tonemapped(toImage(weightedMean(own, others, threads).value, own), centre.scale);
}

// Per pixel, what the learned trust sees of neighbour `k` (learned_trust.h).
std::vector<float> trustFeatures(const Centre& centre, const Contribution& k,
                                 const Image& meanMapped, int distance, bool forward) {
  const Image& own = centre.mapped;
  const int w = own.width, h = own.height;
  const Image mapped = tonemapped(k.image, centre.scale);
  std::vector<float> toOwn = absoluteDifference(mapped, own);
  std::vector<float> toMean = absoluteDifference(mapped, meanMapped);
  for (std::size_t i = 0; i < toOwn.size(); ++i)
    toOwn[i] /= centre.noise[i], toMean[i] /= centre.noise[i];
  BoxSums ownSums(w, h, 1, 1, [&](std::size_t i, double* v) { v[0] = toOwn[i]; });
  const Image& positions = k.resampling.positions;
  std::vector<float> out(own.pixelCount() * kTrustFeatureCount, 0.0f);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const std::size_t i = static_cast<std::size_t>(y) * w + x;
      float* f = &out[i * kTrustFeatureCount];
      const auto box = ownSums.box(x, y);
      const float* p = positions.pixel(x, y);
      const double moved = std::hypot(p[0] - x, p[1] - y);
      double brightness = 0.0;
      for (int c = 0; c < own.channels; ++c) brightness += own.at(x, y, c) / own.channels;
      f[kGuideTrust] = k.resampling.trust.pixels[i];
      f[kOwnDifference] = std::log1p(toOwn[i]);
      f[kOwnDifferenceBox] = static_cast<float>(std::log1p(ownSums.sum(box, 0) / box.pixels()));
      f[kMeanDifference] = std::log1p(toMean[i]);
      f[kLightChange] = k.lightChange.empty() ? 0.0f : std::log1p(k.lightChange[i]);
      f[kMotion] =
          std::isfinite(moved) ? static_cast<float>(std::log1p(std::min(moved, 1e3))) : 0.0f;
      f[kDistance] = distance / 4.0f;
      f[kNoiseLevel] = std::log(centre.noise[i]);
      f[kSpread] = static_cast<float>(std::min(k.fullSpread, 3.0));
      f[kRelit] = k.relight.empty() ? 0.0f : 1.0f;
      f[kBrightness] = static_cast<float>(brightness);
      f[kFuture] = forward ? 1.0f : 0.0f;
    }
  return out;
}

// TemporalOptions::viewDependentMotion.
void applyViewDependence(Contribution& k, const Image& share, double pixels) {
  if (share.empty() || k.weight.empty() || pixels <= 0.0) return;
  const Image still = stillness(k.resampling.positions, pixels);
  for (std::size_t i = 0; i < k.weight.size(); ++i) {
    const double s = share.pixels[i];
    k.weight[i] *= 1.0 - s + s * still.pixels[i];
  }
}

// TemporalOptions::driftThreshold: a kept neighbour's result (and history)
// brought to the frame's light where its light drifted.
void applyDrift(Contribution& k, const Image& own, const TemporalOptions& options) {
  if (options.driftThreshold <= 0.0 || k.weight.empty() || !k.relight.empty()) return;
  Image factor = driftFactor(k.image, own, k.weight, options.driftBox, options.driftThreshold);
  std::vector<unsigned char> drifted = changedPixels(factor);
  if (std::none_of(drifted.begin(), drifted.end(), [](unsigned char d) { return d; })) return;
  k.image = scaled(std::move(k.image), factor);
  if (!k.history.empty()) k.history = scaled(std::move(k.history), factor);
  k.relight = std::move(factor);
  k.drifted = std::move(drifted);
}

void applyLearnedTrust(Contribution& k, const std::vector<float>& features,
                       const LearnedTrust& trust) {
  for (std::size_t i = 0; i < k.weight.size(); ++i) {
    if (k.weight[i] <= 0.0) continue;
    const float w = trust.weigh(&features[i * kTrustFeatureCount]);
    k.weight[i] = w > 0.0f ? k.weight[i] * w : 0.0;  // NaN (a feature of a NaN render): 0
  }
}

// The frame's noisy render and its neighbours', each neighbour's brought in
// at the nearest pixel (resampling would correlate the noise, which the
// network then leaves as blotches) with the weights its result got, and a
// relit or drifted one brought to the frame's light by its result's factor. Also the
// effective number of frames per pixel, (sum w)^2 / sum w^2: the accumulated
// render's variance is the frame's over that.
void accumulateNoisy(const WindowFrame& current, const std::vector<const WindowFrame*>& frames,
                     const std::vector<Contribution>& contributions, int threads,
                     TemporalResult& result) {
  Image ownScratch;
  const Image& own = current.noisy.floats(ownScratch);
  const std::size_t n = own.pixelCount();
  std::vector<double> sum(own.pixels.begin(), own.pixels.end());
  std::vector<double> weight(n, 1.0), squares(n, 1.0);
  // Each pixel summed in the neighbours' order, over bands of rows; `noisy`
  // and `moved` hold one neighbour's render at a time (unpacked in bands too).
  Image noisy(own.width, own.height, own.channels), moved(own.width, own.height, 3);
  for (std::size_t k = 0; k < contributions.size(); ++k) {
    const Contribution& c = contributions[k];
    if (c.weight.empty()) continue;
    forBands(own.height, threads, [&](std::size_t y0, std::size_t y1) {
      frames[k]->noisy.floatsRows(noisy, int(y0), int(y1));
    });
    forBands(own.height, threads, [&](std::size_t y0, std::size_t y1) {
      motion::reprojectNearestRows(noisy, c.resampling.positions, int(y0), int(y1), moved);
      for (std::size_t i = y0 * own.width; i < y1 * own.width; ++i) {
        const double w = c.weight[i];
        if (w <= 0.0) continue;
        weight[i] += w, squares[i] += w * w;
        for (int ch = 0; ch < 3; ++ch) {
          float value = moved.pixels[3 * i + ch];
          if (!c.relight.empty()) value *= c.relight.pixels[3 * i + ch];
          sum[3 * i + ch] += w * value;
        }
      }
    });
  }
  result.history = Image(own.width, own.height, 3);
  result.historyFrames = Image(own.width, own.height, 1);
  forBands(n, threads, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) {
      for (int ch = 0; ch < 3; ++ch)
        result.history.pixels[3 * i + ch] = static_cast<float>(sum[3 * i + ch] / weight[i]);
      result.historyFrames.pixels[i] = static_cast<float>(weight[i] * weight[i] / squares[i]);
    }
  });
  double total = 0.0;  // in pixel order, whatever the threads
  for (float frames : result.historyFrames.pixels) total += frames;
  result.stats.accumulatedFrames = total / std::max<std::size_t>(1, n);
}

// The past neighbours' denoised histories, weighted as their results were
// where the surface stood still.
PastHistories pastHistoriesOf(std::vector<Contribution>& contributions,
                              const std::vector<std::size_t>& indices, const Centre& centre) {
  PastHistories out;
  for (std::size_t n = 0; n < contributions.size(); ++n) {
    Contribution& k = contributions[n];
    if (k.history.empty() || k.weight.empty()) continue;
    std::vector<double> weight = k.weight;
    for (std::size_t i = 0; i < weight.size(); ++i) weight[i] *= k.historyWeight.pixels[i];
    if (std::none_of(weight.begin(), weight.end(), [](double w) { return w > 0.0; })) continue;
    out.images.push_back(std::move(k.history));
    out.weights.push_back(std::move(weight));
    out.frames.push_back(indices[n]);
  }
  if (!out.empty()) out.scale = centre.scale, out.noise = centre.noise;
  return out;
}

// The neighbours' taps and final weights, for filterWith: those left out
// whole carry none.
FilterWeights weightsOf(std::vector<Contribution> contributions,
                        const std::vector<std::size_t>& indices, std::size_t centre,
                        const TemporalOptions& options) {
  FilterWeights out;
  out.centre = centre;
  out.relightBox = options.relightBox;
  out.relightRange = options.relightRange;
  out.driftBox = options.driftBox;
  for (std::size_t k = 0; k < contributions.size(); ++k) {
    Contribution& c = contributions[k];
    if (c.weight.empty()) continue;
    const bool relit = !c.relight.empty() && c.drifted.empty();
    out.neighbours.push_back(
        {indices[k], std::move(c.resampling), relit, std::move(c.drifted), std::move(c.weight)});
  }
  return out;
}

// Per side of `chains` (the past, then the future, each from the centre
// frame out), where each pixel of the centre frame is in each frame after the
// first (chainPositionsAlong): the motion in floats while it is followed,
// over bands of rows on the options' threads. `meanwhile` runs beside the
// motion's conversion, a task of its own.
std::vector<std::vector<Image>> followChains(
    const std::vector<std::vector<const WindowMotion*>>& chains, int width, int height,
    const TemporalOptions& options, const std::function<void()>& meanwhile) {
  std::vector<std::vector<motion::MotionField>> fields(chains.size());
  std::vector<std::pair<std::size_t, std::size_t>> conversions;  // (side, frame)
  for (std::size_t side = 0; side < chains.size(); ++side) {
    if (chains[side].size() < 2) continue;
    fields[side].resize(chains[side].size());
    for (std::size_t k = 0; k < chains[side].size(); ++k) conversions.emplace_back(side, k);
  }
  forEach(conversions.size() + 1, options.threads, [&](std::size_t task) {
    if (task == 0) return meanwhile();
    const auto [side, k] = conversions[task - 1];
    fields[side][k] = chains[side][k]->toField();
  });
  const std::size_t bands = std::max(1, options.threads);
  std::vector<std::vector<motion::FrameGeometry>> geometry(chains.size());
  std::vector<std::vector<Image>> along(chains.size());
  for (std::size_t side = 0; side < chains.size(); ++side) {
    for (const motion::MotionField& field : fields[side])
      geometry[side].push_back({nullptr, &field});
    if (!fields[side].empty()) along[side].assign(fields[side].size() - 1, Image(width, height, 2));
  }
  forEach(chains.size() * bands, options.threads, [&](std::size_t task) {
    const std::size_t side = task / bands, band = task % bands;
    if (along[side].empty()) return;
    motion::chainPositionsRows(geometry[side], side == 1, options.trust,
                               static_cast<int>(band * height / bands),
                               static_cast<int>((band + 1) * height / bands), along[side]);
  });
  return along;
}

}  // namespace

TemporalResult filterFrame(const std::vector<const WindowFrame*>& window, std::size_t centre,
                           const TemporalOptions& options) {
  if (centre >= window.size() || !window[centre])
    throw std::invalid_argument("filterFrame: the centre frame is missing");
  const WindowFrame& current = *window[centre];
  if (!current.viewDependent.empty() &&
      current.viewDependent.pixelCount() != current.denoised.pixelCount())
    throw std::invalid_argument("filterFrame: the view-dependent share differs in size");
  // The neighbours in order (the past nearest first, then the future); a gap
  // ends a side. Each side's motion is followed along its frames at once.
  struct Neighbour {
    const WindowFrame* frame;
    std::size_t index;  // in the window
    bool forward;
    Image positions;  // where each pixel of the frame is in it
  };
  std::vector<Neighbour> neighbours;
  std::vector<std::vector<const WindowMotion*>> chains;  // per side, from the frame out
  for (int side : {-1, 1}) {
    std::vector<const WindowMotion*> chain = {&current.motion};
    for (int k = 1; k <= options.radius; ++k) {
      const long index = static_cast<long>(centre) + side * k;
      if (index < 0 || index >= static_cast<long>(window.size()) || !window[index]) break;
      if (window[index]->motion.empty() || current.motion.empty()) break;
      chain.push_back(&window[index]->motion);
      neighbours.push_back({window[index], static_cast<std::size_t>(index), side > 0, {}});
    }
    chains.push_back(std::move(chain));
  }
  // The centre's own tests' images are made while the motion is converted.
  std::optional<Centre> centreImages;
  std::vector<std::vector<Image>> along =
      followChains(chains, current.denoised.width(), current.denoised.height(), options,
                   [&] { centreImages.emplace(current); });
  for (std::size_t side = 0; side < chains.size(); ++side) {
    const std::size_t first = side == 0 ? 0 : chains[0].size() - 1;
    for (std::size_t k = 0; k < along[side].size(); ++k)
      neighbours[first + k].positions = std::move(along[side][k]);
  }
  Centre& c = *centreImages;
  // The nearest neighbours first: they share the most of the frame and take
  // the longest to test, so the last task left to run alone is a short one.
  std::vector<std::size_t> nearestFirst(neighbours.size());
  std::iota(nearestFirst.begin(), nearestFirst.end(), 0);
  std::stable_sort(nearestFirst.begin(), nearestFirst.end(), [&](std::size_t a, std::size_t b) {
    auto distance = [&](std::size_t n) {
      return std::labs(long(neighbours[n].index) - long(centre));
    };
    return distance(a) < distance(b);
  });
  std::vector<Contribution> contributions(neighbours.size());
  forEach(neighbours.size(), options.threads, [&](std::size_t task) {
    const std::size_t n = nearestFirst[task];
    Neighbour& nb = neighbours[n];
    contributions[n] = contributionOf(c, *nb.frame, std::move(nb.positions), nb.forward, options);
  });
  // The learned trust's view of each neighbour, where it or an observer needs it.
  std::vector<std::vector<float>> features(contributions.size());
  if (options.learnedTrust || options.observeTrust) {
    const Image meanMapped = guideMean(c, contributions, options.threads);
    forEach(contributions.size(), options.threads, [&](std::size_t n) {
      if (contributions[n].weight.empty()) return;
      const long distance = std::labs(long(neighbours[n].index) - long(centre));
      features[n] =
          trustFeatures(c, contributions[n], meanMapped, int(distance), neighbours[n].forward);
    });
  }
  {
    const Image referenceMapped = tonemapped(
        colourReference(c.denoised, contributions, options.colourReference, options.threads),
        c.scale);
    const Image viewDependent = current.viewDependent.toImage();
    forEach(contributions.size(), options.threads, [&](std::size_t n) {
      applyColourTest(contributions[n], referenceMapped, c, options);
      if (options.learnedTrust && !features[n].empty())
        applyLearnedTrust(contributions[n], features[n], *options.learnedTrust);
      applyViewDependence(contributions[n], viewDependent, options.viewDependentMotion);
    });
  }
  c.dropTestImages();
  if (options.observeTrust) {
    TrustSamples samples{c.denoised, c.scale, {}, {}, {}, {}};
    for (std::size_t n = 0; n < contributions.size(); ++n) {
      if (features[n].empty()) continue;
      samples.frames.push_back(neighbours[n].index);
      samples.moved.push_back(contributions[n].image);
      samples.features.push_back(std::move(features[n]));
      samples.weights.push_back(contributions[n].weight);
    }
    options.observeTrust(samples);
  }
  forEach(contributions.size(), options.threads,
          [&](std::size_t n) { applyDrift(contributions[n], c.denoised, options); });

  TemporalResult result;
  {
    const WeightedMean mean = weightedMean(c.denoised, contributions, options.threads);
    result.color = toImage(mean.value, c.denoised);
    double share = 0.0;
    for (double w : mean.weight) share += 1.0 - 1.0 / w;
    result.stats.historyShare = share / std::max<std::size_t>(1, mean.weight.size());
  }
  result.stats.neighbours = static_cast<int>(neighbours.size());
  for (Contribution& k : contributions) {
    result.stats.repeatedNoise += k.verdict == Contribution::Verdict::RepeatedNoise;
    result.stats.changedLight += k.verdict == Contribution::Verdict::ChangedLight;
    result.stats.relit += k.verdict == Contribution::Verdict::Relit;
    result.stats.drifted += !k.drifted.empty();
    const auto used =
        std::count_if(k.weight.begin(), k.weight.end(), [](double w) { return w > 0.0; });
    result.stats.trusted.push_back(double(used) / c.denoised.pixelCount());
    k.image = Image();  // in the mean: only its weights, taps and light factor are needed on
  }
  std::vector<std::size_t> indices;
  for (const Neighbour& nb : neighbours) indices.push_back(nb.index);
  if (options.accumulatedShare > 0.0) {
    std::vector<const WindowFrame*> frames;
    for (const Neighbour& nb : neighbours) frames.push_back(nb.frame);
    accumulateNoisy(current, frames, contributions, options.threads, result);
    result.pastHistories = pastHistoriesOf(contributions, indices, c);
  }
  result.weights = weightsOf(std::move(contributions), indices, centre, options);
  return result;
}

namespace {

// Per pixel, (sum w)^2 / sum w^2 over the frame (weighing 1) and `others`.
Image effectiveFrames(const Image& own, const std::vector<Weighted>& others) {
  const std::size_t n = own.pixelCount();
  std::vector<double> weight(n, 1.0), squares(n, 1.0);
  for (const Weighted& k : others)
    for (std::size_t i = 0; i < std::min(n, k.weight->size()); ++i) {
      const double w = (*k.weight)[i];
      if (w > 0.0) weight[i] += w, squares[i] += w * w;
    }
  Image out(own.width, own.height, 1);
  for (std::size_t i = 0; i < n; ++i)
    out.pixels[i] = static_cast<float>(weight[i] * weight[i] / squares[i]);
  return out;
}

// `images` over the window by `weights`, each neighbour's brought in
// resampled (or at the nearest pixel: a render, whose noise resampling would
// correlate), a relit one by the factor of its `lightOf` image, as filterWith
// and accumulateWith document.
Image combineOver(const char* caller, const FilterWeights& weights,
                  const std::vector<const Image*>& images, const std::vector<const Image*>& lightOf,
                  double stillPixels, bool nearest, const TestedWeights* tested,
                  Image* frames = nullptr) {
  const Image* own = imageAt(images, weights.centre);
  const Image* ownLight = imageAt(lightOf, weights.centre);
  if (!own || !ownLight)
    throw std::invalid_argument(std::string(caller) + ": the centre frame's image is missing");
  // Reserved, so that `others` may point into them as they grow.
  std::vector<Image> moved;
  std::vector<std::vector<double>> gated;  // weights relighting or stillPixels took some of
  moved.reserve(weights.neighbours.size());
  gated.reserve(2 * weights.neighbours.size());
  std::vector<Weighted> others;
  for (std::size_t k = 0; k < weights.neighbours.size(); ++k) {
    const NeighbourWeights& nb = weights.neighbours[k];
    const Image* image = imageAt(images, nb.frame);
    const Image* light = imageAt(lightOf, nb.frame);
    if (!image || !image->sameShape(*own) || !light || !light->sameShape(*ownLight)) continue;
    const std::vector<double>& taken =
        tested && k < tested->size() && !(*tested)[k].empty() ? (*tested)[k] : nb.weight;
    const std::vector<double>* weight = &taken;
    if (stillPixels > 0.0) {
      gated.push_back(taken);
      const Image still = stillness(nb.resampling.positions, stillPixels);
      for (std::size_t i = 0; i < gated.back().size(); ++i) gated.back()[i] *= still.pixels[i];
      weight = &gated.back();
      // Where the whole frame moved, a view-dependent image takes nothing from it.
      if (std::none_of(weight->begin(), weight->end(), [](double w) { return w > 0.0; })) continue;
    }
    Image in = nearest ? motion::reprojectNearest(*image, nb.resampling.positions)
                       : motion::resample(nb.resampling, *image);
    if (nb.relit || !nb.drifted.empty()) {
      // This image's own factor: its light changed by its own ratio.
      const Image lightIn =
          !nearest && image == light ? in : motion::resample(nb.resampling, *light);
      if (!nb.drifted.empty()) {
        in = scaled(std::move(in),
                    driftFactor(lightIn, *ownLight, taken, weights.driftBox, 0.0, &nb.drifted));
      } else {
        const Image factor = relightFactor(lightIn, *ownLight, nb.resampling.trust,
                                           weights.relightBox, weights.relightRange);
        in = scaled(std::move(in), factor);
        gated.push_back(relitWeight(*weight, factor));
        weight = &gated.back();
      }
    }
    moved.push_back(std::move(in));
    others.push_back({&moved.back(), weight});
  }
  if (frames) *frames = effectiveFrames(*own, others);
  return toImage(weightedMean(*own, others).value, *own);
}

}  // namespace

Image filterWith(const FilterWeights& weights, const std::vector<const Image*>& images,
                 double stillPixels, const TestedWeights* tested) {
  return combineOver("filterWith", weights, images, images, stillPixels, false, tested);
}

Image accumulateWith(const FilterWeights& weights, const std::vector<const Image*>& renders,
                     const std::vector<const Image*>& results, double stillPixels, Image* frames,
                     const TestedWeights* tested) {
  return combineOver("accumulateWith", weights, renders, results, stillPixels, true, tested,
                     frames);
}

namespace {

// Per past history, its weight in historyMean. A history is far cleaner than
// the renders filterFrame's tests judged it by: a light that moved since shows
// in it where they saw only noise. It counts where it differs from the
// frame's own by less than the noise its accumulated render still had: fully
// up to lightLow such standard errors, not at all from lightHigh.
std::vector<std::vector<double>> historyTrust(const Image& own, const TemporalResult& result,
                                              const TemporalOptions& options) {
  const PastHistories& past = result.pastHistories;
  for (const Image& image : past.images)
    if (!own.sameShape(image))
      throw std::invalid_argument("historyMean: the images differ in shape");
  std::vector<std::vector<double>> weights = past.weights;
  const Image ownMapped = tonemapped(own, past.scale);
  for (std::size_t k = 0; k < weights.size(); ++k) {
    const std::vector<float> d = mappedDifference(past.images[k], past.scale, ownMapped);
    for (std::size_t i = 0; i < d.size(); ++i) {
      const double error = past.noise[i] * std::sqrt(2.0 / result.historyFrames.pixels[i]);
      weights[k][i] *= fallingWeight(d[i] / error, options.lightLow, options.lightHigh);
    }
  }
  return weights;
}

}  // namespace

FilterWeights pastWeights(const FilterWeights& taps, const std::vector<std::size_t>& frames,
                          std::vector<std::vector<double>> weights) {
  FilterWeights out{taps.centre, taps.relightBox, taps.relightRange, taps.driftBox, {}};
  for (std::size_t k = 0; k < frames.size(); ++k)
    for (const NeighbourWeights& nb : taps.neighbours)
      if (nb.frame == frames[k]) {
        out.neighbours.push_back(nb);
        out.neighbours.back().weight = std::move(weights.at(k));
      }
  return out;
}

FilterWeights historyWeights(const Image& own, const TemporalResult& result,
                             const FilterWeights& taps, const TemporalOptions& options) {
  if (result.pastHistories.empty()) return FilterWeights();
  return pastWeights(taps, result.pastHistories.frames, historyTrust(own, result, options));
}

Image historyMean(const Image& own, const TemporalResult& result, const TemporalOptions& options) {
  const PastHistories& past = result.pastHistories;
  if (past.empty()) return own;
  const std::vector<std::vector<double>> trust = historyTrust(own, result, options);
  std::vector<Weighted> histories;
  for (std::size_t k = 0; k < trust.size(); ++k) histories.push_back({&past.images[k], &trust[k]});
  const std::vector<double> mean = weightedMean(own, histories, options.threads).value;
  Image out = own;
  std::transform(mean.begin(), mean.end(), out.pixels.begin(),
                 [](double v) { return static_cast<float>(v); });
  return out;
}

Image passHistoryShare(const Image& frames, double alone, const TemporalOptions& options) {
  return passHistoryShare(frames, Image(frames.width, frames.height, 1, static_cast<float>(alone)),
                          options);
}

Image passHistoryShare(const Image& frames, const Image& alone, const TemporalOptions& options) {
  if (alone.channels != 1 || alone.pixelCount() != frames.pixelCount())
    throw std::invalid_argument("passHistoryShare: the share alone differs in shape");
  const double full = options.accumulatedShare;
  Image out = frames;
  for (std::size_t i = 0; i < out.pixels.size(); ++i) {
    const double own = std::min<double>(alone.pixels[i], full);
    out.pixels[i] =
        static_cast<float>(own + (full - own) * std::clamp(frames.pixels[i] - 1.0, 0.0, 1.0));
  }
  return out;
}

Image viewDependentAlone(const Image& viewDependent, const TemporalOptions& options) {
  if (viewDependent.channels != 1)
    throw std::invalid_argument("viewDependentAlone: the view-dependent share has one channel");
  Image out(viewDependent.width, viewDependent.height, 1,
            static_cast<float>(options.viewDependentShareAlone));
  if (options.viewDependentShareFull <= 0.0) return out;
  for (std::size_t i = 0; i < out.pixels.size(); ++i)
    out.pixels[i] *= static_cast<float>(
        std::clamp(viewDependent.pixels[i] / options.viewDependentShareFull, 0.0, 1.0));
  return out;
}

Image blendWithHistory(const Image& filtered, const Image& accumulated, const Image& share) {
  if (!filtered.sameShape(accumulated) || share.channels != 1 ||
      share.pixelCount() != filtered.pixelCount())
    throw std::invalid_argument("blendWithHistory: the images differ in shape");
  Image out = filtered;
  const int channels = out.channels;
  for (std::size_t i = 0; i < out.pixels.size(); ++i) {
    const double s = share.pixels[i / channels];
    out.pixels[i] = static_cast<float>((1.0 - s) * filtered.pixels[i] + s * accumulated.pixels[i]);
  }
  return out;
}

Image blendWithHistory(const Image& filtered, const Image& accumulated, double share) {
  if (!filtered.sameShape(accumulated))
    throw std::invalid_argument("blendWithHistory: the images differ in shape");
  Image out = filtered;
  for (std::size_t i = 0; i < out.pixels.size(); ++i)
    out.pixels[i] =
        static_cast<float>((1.0 - share) * filtered.pixels[i] + share * accumulated.pixels[i]);
  return out;
}

TestedWeights passLightTested(const FilterWeights& weights,
                              const std::vector<const Image*>& renders,
                              const std::vector<const Image*>& results,
                              const TemporalOptions& options) {
  const Image* render = imageAt(renders, weights.centre);
  const Image* result = imageAt(results, weights.centre);
  auto drifted = [](const NeighbourWeights& nb) { return !nb.drifted.empty(); };
  if (!render || !result || options.passLightHigh <= 0.0 ||
      std::none_of(weights.neighbours.begin(), weights.neighbours.end(), drifted))
    return {};
  const double scale = tonemap::oidnExposure(*result);
  const Image mapped = tonemapped(*render, scale);
  const Image residual = difference(mapped, tonemapped(*result, scale));
  TestedWeights out(weights.neighbours.size());
  for (std::size_t k = 0; k < weights.neighbours.size(); ++k) {
    const NeighbourWeights& nb = weights.neighbours[k];
    const Image* theirs = imageAt(renders, nb.frame);
    const Image* theirResult = imageAt(results, nb.frame);
    if (!drifted(nb) || !theirs || !theirResult) continue;
    // Tested as the filter takes it: brought to the frame's light.
    const Image factor = driftFactor(motion::resample(nb.resampling, *theirResult), *result,
                                     nb.weight, weights.driftBox, 0.0, &nb.drifted);
    const Image movedMapped = tonemapped(
        scaled(motion::reprojectNearest(*theirs, nb.resampling.positions), factor), scale);
    const Image movedResidual = difference(
        movedMapped,
        tonemapped(scaled(motion::reprojectNearest(*theirResult, nb.resampling.positions), factor),
                   scale));
    const std::vector<float> z = lightChange(mapped, movedMapped, nb.resampling.trust, residual,
                                             movedResidual, options.lightBox);
    out[k] = nb.weight;
    for (std::size_t i = 0; i < z.size(); ++i)
      out[k][i] *= fallingWeight(z[i], options.passLightLow, options.passLightHigh);
  }
  return out;
}

}  // namespace dn::temporal
