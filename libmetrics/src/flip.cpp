// FLIP and HDR-FLIP. The steps, constants and float arithmetic follow the
// published description and NVIDIA's flip-evaluator so that the two agree to
// float rounding; the filters run separably over planar buffers, in parallel
// over rows.
#include "dn/flip.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "dn/parallel.h"
#include "dn/tonemap.h"

namespace dn::flip {

namespace {

constexpr float kPi = 3.14159265358979f;

// FLIP's constants (paper, Table 1).
constexpr float kColorExponent = 0.7f;          // q_c
constexpr float kColorCutoffFraction = 0.4f;    // p_c
constexpr float kColorCutoffError = 0.95f;      // p_t
constexpr float kFeatureWidthDegrees = 0.082f;  // w
constexpr float kFeatureExponent = 0.5f;        // q_f

// Contrast sensitivity functions in the spatial domain: sums of Gaussians
// a * sqrt(pi / b) * exp(-pi^2 x^2 / b), with x in degrees of visual angle.
struct GaussianTerm {
  float a, b;
};
constexpr GaussianTerm kCsfAchromatic{1.0f, 0.0047f};
constexpr GaussianTerm kCsfRedGreen{1.0f, 0.0053f};
constexpr GaussianTerm kCsfBlueYellow1{34.1f, 0.04f};
constexpr GaussianTerm kCsfBlueYellow2{13.5f, 0.025f};
constexpr float kCsfLargestB = 0.04f;

// HDR-FLIP: exposures are chosen so that luminances reach this tonemapped value.
constexpr float kExposureTarget = 0.85f;

struct Vec3 {
  float x, y, z;
};

// D65 white point and its inverse.
constexpr Vec3 kWhite{0.950428545f, 1.0f, 1.088900371f};
constexpr Vec3 kInverseWhite{1.052156925f, 1.0f, 0.918357670f};

Vec3 linearRgbToXyz(Vec3 c) {
  return {(10135552.0f / 24577794.0f) * c.x + (8788810.0f / 24577794.0f) * c.y +
              (4435075.0f / 24577794.0f) * c.z,
          (2613072.0f / 12288897.0f) * c.x + (8788810.0f / 12288897.0f) * c.y +
              (887015.0f / 12288897.0f) * c.z,
          (1425312.0f / 73733382.0f) * c.x + (8788810.0f / 73733382.0f) * c.y +
              (70074185.0f / 73733382.0f) * c.z};
}

Vec3 xyzToLinearRgb(Vec3 c) {
  return {3.241003275f * c.x - 1.537398934f * c.y - 0.498615861f * c.z,
          -0.969224334f * c.x + 1.875930071f * c.y + 0.041554224f * c.z,
          0.055639423f * c.x - 0.204011202f * c.y + 1.057148933f * c.z};
}

// Linear RGB to YCxCz, the opponent space FLIP filters in.
Vec3 linearRgbToYCxCz(Vec3 rgb) {
  const Vec3 xyz = linearRgbToXyz(rgb);
  const float x = xyz.x * kInverseWhite.x, y = xyz.y * kInverseWhite.y, z = xyz.z * kInverseWhite.z;
  return {116.0f * y - 16.0f, 500.0f * (x - y), 200.0f * (y - z)};
}

Vec3 yCxCzToXyz(Vec3 c) {
  const float y = (c.x + 16.0f) / 116.0f;
  return {(y + c.y / 500.0f) * kWhite.x, y * kWhite.y, (y - c.z / 200.0f) * kWhite.z};
}

float labCompand(float t) {
  constexpr float delta = 6.0f / 29.0f;
  return t > delta * delta * delta ? std::pow(t, 1.0f / 3.0f)
                                   : t / (3.0f * delta * delta) + 4.0f / 29.0f;
}

// CIELAB with the Hunt effect applied: chroma scales with lightness.
Vec3 huntAdjustedLab(Vec3 linearRgb) {
  const Vec3 xyz = linearRgbToXyz(linearRgb);
  const float fx = labCompand(xyz.x * kInverseWhite.x);
  const float fy = labCompand(xyz.y * kInverseWhite.y);
  const float fz = labCompand(xyz.z * kInverseWhite.z);
  const float lightness = 116.0f * fy - 16.0f;
  const float hunt = 0.01f * lightness;
  return {lightness, hunt * 500.0f * (fx - fy), hunt * 200.0f * (fy - fz)};
}

// HyAB: city-block distance in lightness plus Euclidean distance in chroma.
float hyab(Vec3 a, Vec3 b) {
  const float da = a.y - b.y, db = a.z - b.z;
  return std::fabs(a.x - b.x) + std::sqrt(da * da + db * db);
}

float clamp01(float v) { return std::min(std::max(v, 0.0f), 1.0f); }

// The largest color difference FLIP can see: pure green against pure blue.
float maxColorDifference() {
  return std::pow(hyab(huntAdjustedLab({0.0f, 1.0f, 0.0f}), huntAdjustedLab({0.0f, 0.0f, 1.0f})),
                  kColorExponent);
}

// Rational tonemapping curves (a x^2 + b x + c) / (d x^2 + e x + f). Reinhard
// only uses its row to pick exposures; the curve itself works on luminance.
using RationalCurve = std::array<float, 6>;
RationalCurve rationalCurve(Tonemapper tonemapper) {
  switch (tonemapper) {
    case Tonemapper::Reinhard:
      return {0.0f, 1.0f, 0.0f, 0.0f, 1.0f, 1.0f};
    case Tonemapper::Hable:
      return {0.231683f, 0.013791f, 0.0f, 0.18f, 0.3f, 0.018f};
    case Tonemapper::Aces:
      break;
  }
  // Narkowicz's ACES fit with its 0.6 pre-exposure cancelled.
  return {0.6f * 0.6f * 2.51f, 0.6f * 0.03f, 0.0f, 0.6f * 0.6f * 2.43f, 0.6f * 0.59f, 0.14f};
}

float luminance(Vec3 c) { return 0.2126f * c.x + 0.7152f * c.y + 0.0722f * c.z; }

// How an input pixel becomes the linear RGB in [0,1] that LDR-FLIP compares.
struct DisplayMapping {
  bool srgbInput = true;  // else exposed and tonemapped linear radiance
  float exposureScale = 1.0f;
  Tonemapper tonemapper = Tonemapper::Aces;
  RationalCurve curve{};

  Vec3 operator()(const float* in) const {
    if (srgbInput)
      return {clamp01(tonemap::srgbDecode(in[0])), clamp01(tonemap::srgbDecode(in[1])),
              clamp01(tonemap::srgbDecode(in[2]))};
    // Capped so that the curves' squares stay finite; they saturate long before.
    const auto expose = [this](float v) {
      return std::min(std::max(v, 0.0f) * exposureScale, 1e15f);
    };
    Vec3 c{expose(in[0]), expose(in[1]), expose(in[2])};
    if (tonemapper == Tonemapper::Reinhard) {
      const float scale = 1.0f / (1.0f + luminance(c));
      return {clamp01(c.x * scale), clamp01(c.y * scale), clamp01(c.z * scale)};
    }
    const auto map = [this](float v) {
      return clamp01((v * v * curve[0] + v * curve[1] + curve[2]) /
                     (v * v * curve[3] + v * curve[4] + curve[5]));
    };
    return {map(c.x), map(c.y), map(c.z)};
  }
};

// 1D taps of the separated contrast sensitivity filters. The blue-yellow
// filter is a sum of two Gaussians, so it separates into two x-y pairs whose
// products add up (see NVIDIA's note on separated convolutions).
struct SpatialFilters {
  int radius = 0;
  std::vector<float> achromatic, redGreen, blueYellow1, blueYellow2;
};

SpatialFilters makeSpatialFilters(float pixelsPerDegree) {
  SpatialFilters f;
  f.radius = static_cast<int>(
      std::ceil(3.0f * std::sqrt(kCsfLargestB / (2.0f * kPi * kPi)) * pixelsPerDegree));
  const int width = 2 * f.radius + 1;
  const auto gaussian = [](float x2, GaussianTerm g) {
    return g.a * std::sqrt(kPi / g.b) * std::exp(-kPi * kPi * x2 / g.b);
  };
  // Square root of the amplitude, so that the x and y factors multiply back to it.
  const auto halfGaussian = [](float x2, GaussianTerm g) {
    return std::sqrt(g.a * std::sqrt(kPi / g.b)) * std::exp(-kPi * kPi * x2 / g.b);
  };
  float sumY = 0.0f, sumCx = 0.0f, sumCz1 = 0.0f, sumCz2 = 0.0f;
  for (int i = 0; i < width; ++i) {
    const float x = static_cast<float>(i - f.radius) / pixelsPerDegree;
    const float x2 = x * x;
    f.achromatic.push_back(gaussian(x2, kCsfAchromatic));
    f.redGreen.push_back(gaussian(x2, kCsfRedGreen));
    f.blueYellow1.push_back(halfGaussian(x2, kCsfBlueYellow1));
    f.blueYellow2.push_back(halfGaussian(x2, kCsfBlueYellow2));
    sumY += f.achromatic.back();
    sumCx += f.redGreen.back();
    sumCz1 += f.blueYellow1.back();
    sumCz2 += f.blueYellow2.back();
  }
  // Each 2D filter sums to 1; the two blue-yellow pairs share one factor.
  const float normCz = 1.0f / std::sqrt(sumCz1 * sumCz1 + sumCz2 * sumCz2);
  for (int i = 0; i < width; ++i) {
    f.achromatic[i] *= 1.0f / sumY;
    f.redGreen[i] *= 1.0f / sumCx;
    f.blueYellow1[i] *= normCz;
    f.blueYellow2[i] *= normCz;
  }
  return f;
}

// Gaussian and its first and second derivatives, for edge and point detection.
struct FeatureFilters {
  int radius = 0;
  std::vector<float> gaussian, firstDerivative, secondDerivative;
};

// Scales positive and negative weights separately so they sum to +1 and -1.
void balanceSigns(std::vector<float>& taps) {
  float positive = 0.0f, negative = 0.0f;
  for (float t : taps) (t > 0.0f ? positive : negative) += std::fabs(t);
  for (float& t : taps) t /= (t > 0.0f ? positive : negative);
}

FeatureFilters makeFeatureFilters(float pixelsPerDegree) {
  FeatureFilters f;
  const float sigma = 0.5f * kFeatureWidthDegrees * pixelsPerDegree;
  f.radius = static_cast<int>(std::ceil(3.0f * sigma));
  float sum = 0.0f;
  for (int i = -f.radius; i <= f.radius; ++i) {
    const float x = static_cast<float>(i);
    const float g = std::exp(-(x * x) / (2.0f * sigma * sigma));
    f.gaussian.push_back(g);
    f.firstDerivative.push_back(-x * g);
    f.secondDerivative.push_back((x * x / (sigma * sigma) - 1.0f) * g);
    sum += g;
  }
  for (float& g : f.gaussian) g /= sum;
  balanceSigns(f.firstDerivative);
  balanceSigns(f.secondDerivative);
  return f;
}

// One image in YCxCz, one plane per channel, plus luminance scaled to [0,1]
// for the feature detectors.
struct OpponentPlanes {
  std::vector<float> y, cx, cz, lightness;
};

// Each image filtered along rows; the column pass finishes the 2D filters.
struct RowFiltered {
  std::vector<float> y, cx, cz1, cz2;  // contrast sensitivity
  std::vector<float> dx, ddx, smooth;  // feature detection on lightness
};

// Copies a row into buf with `pad` clamped edge values on each side.
void padRow(const float* row, int width, int pad, float* buf) {
  std::fill(buf, buf + pad, row[0]);
  std::copy(row, row + width, buf + pad);
  std::fill(buf + pad + width, buf + 2 * pad + width, row[width - 1]);
}

// out[x] = sum_k taps[k] * sourceRow(k)[x]. Sums run over blocks of x kept in
// registers, in tap order (as the reference does, so rounding matches).
template <class SourceRow>
void weightedRowSum(SourceRow sourceRow, const std::vector<float>& taps, int width,
                    float* __restrict out) {
  constexpr int kBlock = 32;
  for (int x0 = 0; x0 < width; x0 += kBlock) {
    float sum[kBlock] = {};
    const int n = std::min(kBlock, width - x0);
    for (std::size_t k = 0; k < taps.size(); ++k) {
      const float w = taps[k];
      const float* __restrict src = sourceRow(static_cast<int>(k)) + x0;
      if (n == kBlock)
        for (int j = 0; j < kBlock; ++j) sum[j] += w * src[j];
      else
        for (int j = 0; j < n; ++j) sum[j] += w * src[j];
    }
    std::copy(sum, sum + n, out + x0);
  }
}

// out[x] = sum_k taps[k] * in[x + k - r]; `in` points at x = 0 of a padded row.
void convolveRow(const float* in, const std::vector<float>& taps, int width, float* out) {
  const int radius = static_cast<int>(taps.size()) / 2;
  weightedRowSum([&](int k) { return in + k - radius; }, taps, width, out);
}

// out[x] = sum_k taps[k] * plane[clamp(y + k - r)][x].
void convolveColumn(const std::vector<float>& plane, int width, int height, int y,
                    const std::vector<float>& taps, float* out) {
  const int radius = static_cast<int>(taps.size()) / 2;
  weightedRowSum(
      [&](int k) {
        const int row = std::min(std::max(y + k - radius, 0), height - 1);
        return plane.data() + static_cast<std::size_t>(row) * width;
      },
      taps, width, out);
}

// LDR-FLIP on images of one size, reusing its buffers across calls (HDR-FLIP
// runs it once per exposure).
class LdrFlip {
 public:
  LdrFlip(int width, int height, float pixelsPerDegree)
      : width_(width),
        height_(height),
        spatial_(makeSpatialFilters(pixelsPerDegree)),
        feature_(makeFeatureFilters(pixelsPerDegree)),
        maxColor_(maxColorDifference()) {
    for (int i = 0; i < 2; ++i) {
      allocate(opponent_[i]);
      allocate(rows_[i]);
    }
  }

  // error = max(error, LDR-FLIP of the two images as `display` shows them).
  void accumulateMax(const Image& reference, const Image& test, const DisplayMapping& display,
                     float* error) {
    toOpponent(reference, display, opponent_[0]);
    toOpponent(test, display, opponent_[1]);
    parallelFor(height_, [&](int y0, int y1) {
      filterRows(opponent_[0], rows_[0], y0, y1);
      filterRows(opponent_[1], rows_[1], y0, y1);
    });
    parallelFor(height_, [&](int y0, int y1) { filterColumnsAndCompare(error, y0, y1); });
  }

 private:
  std::size_t planeSize() const { return static_cast<std::size_t>(width_) * height_; }

  void allocate(OpponentPlanes& p) {
    for (auto* v : {&p.y, &p.cx, &p.cz, &p.lightness}) v->resize(planeSize());
  }
  void allocate(RowFiltered& p) {
    for (auto* v : {&p.y, &p.cx, &p.cz1, &p.cz2, &p.dx, &p.ddx, &p.smooth}) v->resize(planeSize());
  }

  void toOpponent(const Image& image, const DisplayMapping& display, OpponentPlanes& out) {
    parallelFor(height_, [&](int y0, int y1) {
      for (int y = y0; y < y1; ++y)
        for (int x = 0; x < width_; ++x) {
          const std::size_t i = static_cast<std::size_t>(y) * width_ + x;
          const Vec3 c = linearRgbToYCxCz(display(image.pixel(x, y)));
          out.y[i] = c.x;
          out.cx[i] = c.y;
          out.cz[i] = c.z;
          out.lightness[i] = c.x * (1.0f / 116.0f) + 16.0f / 116.0f;
        }
    });
  }

  void filterRows(const OpponentPlanes& in, RowFiltered& out, int y0, int y1) const {
    const int pad = std::max(spatial_.radius, feature_.radius);
    const std::size_t padded = static_cast<std::size_t>(width_) + 2 * pad;
    std::vector<float> y(padded), cx(padded), cz(padded), lightness(padded);
    for (int row = y0; row < y1; ++row) {
      const std::size_t offset = static_cast<std::size_t>(row) * width_;
      padRow(in.y.data() + offset, width_, pad, y.data());
      padRow(in.cx.data() + offset, width_, pad, cx.data());
      padRow(in.cz.data() + offset, width_, pad, cz.data());
      padRow(in.lightness.data() + offset, width_, pad, lightness.data());
      convolveRow(y.data() + pad, spatial_.achromatic, width_, out.y.data() + offset);
      convolveRow(cx.data() + pad, spatial_.redGreen, width_, out.cx.data() + offset);
      convolveRow(cz.data() + pad, spatial_.blueYellow1, width_, out.cz1.data() + offset);
      convolveRow(cz.data() + pad, spatial_.blueYellow2, width_, out.cz2.data() + offset);
      convolveRow(lightness.data() + pad, feature_.firstDerivative, width_, out.dx.data() + offset);
      convolveRow(lightness.data() + pad, feature_.secondDerivative, width_,
                  out.ddx.data() + offset);
      convolveRow(lightness.data() + pad, feature_.gaussian, width_, out.smooth.data() + offset);
    }
  }

  // Column pass of both filters for both images, then the per-pixel error.
  void filterColumnsAndCompare(float* error, int y0, int y1) const {
    enum Row { kY, kCx, kCz1, kCz2, kDx, kDdx, kDy, kDdy, kRows };
    std::vector<float> scratch(static_cast<std::size_t>(2) * kRows * width_);
    const auto row = [&](int image, Row r) {
      return scratch.data() + (static_cast<std::size_t>(image) * kRows + r) * width_;
    };
    const float pcMax = kColorCutoffFraction * maxColor_;
    for (int y = y0; y < y1; ++y) {
      for (int i = 0; i < 2; ++i) {
        const RowFiltered& in = rows_[i];
        convolveColumn(in.y, width_, height_, y, spatial_.achromatic, row(i, kY));
        convolveColumn(in.cx, width_, height_, y, spatial_.redGreen, row(i, kCx));
        convolveColumn(in.cz1, width_, height_, y, spatial_.blueYellow1, row(i, kCz1));
        convolveColumn(in.cz2, width_, height_, y, spatial_.blueYellow2, row(i, kCz2));
        convolveColumn(in.dx, width_, height_, y, feature_.gaussian, row(i, kDx));
        convolveColumn(in.ddx, width_, height_, y, feature_.gaussian, row(i, kDdx));
        convolveColumn(in.smooth, width_, height_, y, feature_.firstDerivative, row(i, kDy));
        convolveColumn(in.smooth, width_, height_, y, feature_.secondDerivative, row(i, kDdy));
      }
      float* out = error + static_cast<std::size_t>(y) * width_;
      for (int x = 0; x < width_; ++x) {
        Vec3 lab[2];
        float edge[2], point[2];
        for (int i = 0; i < 2; ++i) {
          const Vec3 filtered{row(i, kY)[x], row(i, kCx)[x], row(i, kCz1)[x] + row(i, kCz2)[x]};
          const Vec3 rgb = xyzToLinearRgb(yCxCzToXyz(filtered));
          lab[i] = huntAdjustedLab({clamp01(rgb.x), clamp01(rgb.y), clamp01(rgb.z)});
          edge[i] = std::sqrt(row(i, kDx)[x] * row(i, kDx)[x] + row(i, kDy)[x] * row(i, kDy)[x]);
          point[i] =
              std::sqrt(row(i, kDdx)[x] * row(i, kDdx)[x] + row(i, kDdy)[x] * row(i, kDdy)[x]);
        }
        const float color =
            remapColorDifference(std::pow(hyab(lab[0], lab[1]), kColorExponent), pcMax);
        const float featureDifference =
            std::max(std::fabs(edge[0] - edge[1]), std::fabs(point[0] - point[1]));
        static_assert(kFeatureExponent == 0.5f, "the square root below is x^q_f");
        const float feature = std::sqrt(featureDifference * (1.0f / std::sqrt(2.0f)));
        out[x] = std::max(out[x], std::pow(color, 1.0f - feature));
      }
    }
  }

  // Maps [0, pcMax) linearly to [0, p_t) and [pcMax, cMax] to [p_t, 1], so
  // that small differences get most of the range.
  float remapColorDifference(float difference, float pcMax) const {
    if (difference < pcMax) return difference * (kColorCutoffError / pcMax);
    return kColorCutoffError +
           (difference - pcMax) / (maxColor_ - pcMax) * (1.0f - kColorCutoffError);
  }

  int width_, height_;
  SpatialFilters spatial_;
  FeatureFilters feature_;
  float maxColor_;
  OpponentPlanes opponent_[2];
  RowFiltered rows_[2];
};

void requireComparable(const Image& reference, const Image& test, const char* what) {
  if (reference.empty() || test.empty())
    throw std::invalid_argument(std::string(what) + ": empty image");
  if (reference.width != test.width || reference.height != test.height)
    throw std::invalid_argument(
        std::string(what) + ": image sizes differ (" + std::to_string(reference.width) + "x" +
        std::to_string(reference.height) + " vs " + std::to_string(test.width) + "x" +
        std::to_string(test.height) + ")");
  if (reference.channels < 3 || test.channels < 3)
    throw std::invalid_argument(std::string(what) + ": images need at least 3 channels");
}

void requirePositivePpd(double pixelsPerDegree, const char* what) {
  if (!(pixelsPerDegree > 0.0) || !std::isfinite(pixelsPerDegree))
    throw std::invalid_argument(std::string(what) + ": pixels per degree must be positive");
}

// Radiance must be finite: an infinite or NaN pixel has no place in the exposure range.
void requireFinite(const Image& image, const char* what) {
  for (float v : image.pixels)
    if (!std::isfinite(v))
      throw std::invalid_argument(std::string(what) + " has NaN or infinite values");
}

// Larger root of curve(x) = target, the input the tonemapper maps to target.
float tonemapperInputFor(float target, const RationalCurve& c) {
  const float a = c[0] - target * c[3];
  const float b = c[1] - target * c[4];
  const float k = c[2] - target * c[5];
  if (a == 0.0f) return -k / b;
  const float mid = -0.5f * (b / a);
  return mid + std::sqrt(mid * mid - k / a);
}

// Sorts floats in O(n): three 11-bit radix passes over keys whose unsigned
// order is the float order (error maps have millions of pixels).
void radixSort(std::vector<float>& values) {
  constexpr std::uint32_t kSign = 0x80000000u;
  std::vector<std::uint32_t> keys(values.size()), buffer(values.size());
  for (std::size_t i = 0; i < values.size(); ++i) {
    std::uint32_t bits;
    std::memcpy(&bits, &values[i], sizeof bits);
    keys[i] = (bits & kSign) ? ~bits : (bits | kSign);
  }
  for (int shift = 0; shift < 32; shift += 11) {
    std::vector<std::size_t> start(2049, 0);
    for (std::uint32_t k : keys) ++start[((k >> shift) & 2047u) + 1];
    for (std::size_t b = 1; b < start.size(); ++b) start[b] += start[b - 1];
    for (std::uint32_t k : keys) buffer[start[(k >> shift) & 2047u]++] = k;
    keys.swap(buffer);
  }
  for (std::size_t i = 0; i < values.size(); ++i) {
    const std::uint32_t bits = (keys[i] & kSign) ? (keys[i] & ~kSign) : ~keys[i];
    std::memcpy(&values[i], &bits, sizeof bits);
  }
}

}  // namespace

ExposureRange exposureRange(const Image& referenceLinear, const HdrOptions& options) {
  if (referenceLinear.empty() || referenceLinear.channels < 3)
    throw std::invalid_argument("HDR-FLIP: reference needs at least 3 channels");
  requireFinite(referenceLinear, "HDR-FLIP: reference");
  ExposureRange range;
  if (!options.startExposure || !options.stopExposure) {
    std::vector<float> luminances(referenceLinear.pixelCount());
    float brightest = 0.0f;
    for (std::size_t i = 0; i < luminances.size(); ++i) {
      const float* p = &referenceLinear.pixels[i * referenceLinear.channels];
      luminances[i] = luminance({std::max(p[0], 0.0f), std::max(p[1], 0.0f), std::max(p[2], 0.0f)});
      brightest = std::max(brightest, luminances[i]);
    }
    const auto middle = luminances.begin() + luminances.size() / 2;
    std::nth_element(luminances.begin(), middle, luminances.end());
    // flip-evaluator 1.7 floors the median at float epsilon (mostly black references).
    const float median = std::max(*middle, std::numeric_limits<float>::epsilon());
    const float input = tonemapperInputFor(kExposureTarget, rationalCurve(options.tonemapper));
    if (brightest > 0.0f) {
      range.start = std::log2(input / brightest);
      range.stop = std::log2(input / median);
    }  // else an all-black reference, where the reference fails: keep [0, 0]
  }
  if (options.startExposure) range.start = *options.startExposure;
  if (options.stopExposure) range.stop = *options.stopExposure;
  if (!std::isfinite(range.start) || !std::isfinite(range.stop) || range.start > range.stop)
    throw std::invalid_argument("HDR-FLIP: start exposure must be finite and not above stop");
  if (options.numExposures) {
    if (*options.numExposures < 1)
      throw std::invalid_argument("HDR-FLIP: number of exposures must be at least 1");
    range.count = *options.numExposures;
  } else {
    range.count = static_cast<int>(std::max(
        2.0f, std::ceil(static_cast<float>(range.stop) - static_cast<float>(range.start))));
  }
  return range;
}

Image ldrErrorMap(const Image& referenceSrgb, const Image& testSrgb, double pixelsPerDegree) {
  requireComparable(referenceSrgb, testSrgb, "LDR-FLIP");
  requirePositivePpd(pixelsPerDegree, "LDR-FLIP");
  Image error(referenceSrgb.width, referenceSrgb.height, 1, 0.0f);
  LdrFlip flip(error.width, error.height, static_cast<float>(pixelsPerDegree));
  flip.accumulateMax(referenceSrgb, testSrgb, DisplayMapping{}, error.pixels.data());
  return error;
}

Image hdrErrorMap(const Image& referenceLinear, const Image& testLinear,
                  const HdrOptions& options) {
  requireComparable(referenceLinear, testLinear, "HDR-FLIP");
  requirePositivePpd(options.pixelsPerDegree, "HDR-FLIP");
  requireFinite(testLinear, "HDR-FLIP: test");
  const ExposureRange range = exposureRange(referenceLinear, options);
  Image error(referenceLinear.width, referenceLinear.height, 1, 0.0f);
  LdrFlip flip(error.width, error.height, static_cast<float>(options.pixelsPerDegree));
  const float start = static_cast<float>(range.start);
  const float step =
      range.count > 1 ? static_cast<float>(range.stop - range.start) / (range.count - 1) : 0.0f;
  for (int i = 0; i < range.count; ++i) {
    DisplayMapping display;
    display.srgbInput = false;
    display.exposureScale = std::pow(2.0f, start + i * step);
    display.tonemapper = options.tonemapper;
    display.curve = rationalCurve(options.tonemapper);
    flip.accumulateMax(referenceLinear, testLinear, display, error.pixels.data());
  }
  return error;
}

Stats statistics(const Image& errorMap) {
  if (errorMap.empty() || errorMap.channels < 1)
    throw std::invalid_argument("FLIP statistics: empty error map");
  std::vector<float> values(errorMap.pixelCount());
  for (std::size_t i = 0; i < values.size(); ++i)
    values[i] = errorMap.pixels[i * errorMap.channels];
  radixSort(values);

  Stats s;
  double sum = 0.0;
  for (float v : values) sum += v;
  s.mean = sum / static_cast<double>(values.size());
  s.min = values.front();
  s.max = values.back();

  const auto percentile = [&](double p) {
    const double position = p * static_cast<double>(values.size() - 1);
    const std::size_t lo = static_cast<std::size_t>(position);
    const std::size_t hi = std::min(lo + 1, values.size() - 1);
    return values[lo] + (position - static_cast<double>(lo)) * (values[hi] - values[lo]);
  };
  s.p25 = percentile(0.25);
  s.p50 = percentile(0.50);
  s.p75 = percentile(0.75);
  s.p95 = percentile(0.95);
  s.p99 = percentile(0.99);

  // The smallest value at which the running sum of sorted errors passes p of the total.
  const auto weightedPercentile = [&](double p) {
    double running = 0.0;
    for (float v : values) {
      running += v;
      if (running > p * sum) return static_cast<double>(v);
    }
    return 0.0;
  };
  s.weightedQuartile1 = weightedPercentile(0.25);
  s.weightedMedian = weightedPercentile(0.50);
  s.weightedQuartile3 = weightedPercentile(0.75);
  return s;
}

namespace {

// Matplotlib's magma colormap (van der Walt, Smith, Firing; CC0), sRGB-encoded.
constexpr float kMagma[256][3] = {
    {0.001462f, 0.000466f, 0.013866f}, {0.002258f, 0.001295f, 0.018331f},
    {0.003279f, 0.002305f, 0.023708f}, {0.004512f, 0.003490f, 0.029965f},
    {0.005950f, 0.004843f, 0.037130f}, {0.007588f, 0.006356f, 0.044973f},
    {0.009426f, 0.008022f, 0.052844f}, {0.011465f, 0.009828f, 0.060750f},
    {0.013708f, 0.011771f, 0.068667f}, {0.016156f, 0.013840f, 0.076603f},
    {0.018815f, 0.016026f, 0.084584f}, {0.021692f, 0.018320f, 0.092610f},
    {0.024792f, 0.020715f, 0.100676f}, {0.028123f, 0.023201f, 0.108787f},
    {0.031696f, 0.025765f, 0.116965f}, {0.035520f, 0.028397f, 0.125209f},
    {0.039608f, 0.031090f, 0.133515f}, {0.043830f, 0.033830f, 0.141886f},
    {0.048062f, 0.036607f, 0.150327f}, {0.052320f, 0.039407f, 0.158841f},
    {0.056615f, 0.042160f, 0.167446f}, {0.060949f, 0.044794f, 0.176129f},
    {0.065330f, 0.047318f, 0.184892f}, {0.069764f, 0.049726f, 0.193735f},
    {0.074257f, 0.052017f, 0.202660f}, {0.078815f, 0.054184f, 0.211667f},
    {0.083446f, 0.056225f, 0.220755f}, {0.088155f, 0.058133f, 0.229922f},
    {0.092949f, 0.059904f, 0.239164f}, {0.097833f, 0.061531f, 0.248477f},
    {0.102815f, 0.063010f, 0.257854f}, {0.107899f, 0.064335f, 0.267289f},
    {0.113094f, 0.065492f, 0.276784f}, {0.118405f, 0.066479f, 0.286321f},
    {0.123833f, 0.067295f, 0.295879f}, {0.129380f, 0.067935f, 0.305443f},
    {0.135053f, 0.068391f, 0.315000f}, {0.140858f, 0.068654f, 0.324538f},
    {0.146785f, 0.068738f, 0.334011f}, {0.152839f, 0.068637f, 0.343404f},
    {0.159018f, 0.068354f, 0.352688f}, {0.165308f, 0.067911f, 0.361816f},
    {0.171713f, 0.067305f, 0.370771f}, {0.178212f, 0.066576f, 0.379497f},
    {0.184801f, 0.065732f, 0.387973f}, {0.191460f, 0.064818f, 0.396152f},
    {0.198177f, 0.063862f, 0.404009f}, {0.204935f, 0.062907f, 0.411514f},
    {0.211718f, 0.061992f, 0.418647f}, {0.218512f, 0.061158f, 0.425392f},
    {0.225302f, 0.060445f, 0.431742f}, {0.232077f, 0.059889f, 0.437695f},
    {0.238826f, 0.059517f, 0.443256f}, {0.245543f, 0.059352f, 0.448436f},
    {0.252220f, 0.059415f, 0.453248f}, {0.258857f, 0.059706f, 0.457710f},
    {0.265447f, 0.060237f, 0.461840f}, {0.271994f, 0.060994f, 0.465660f},
    {0.278493f, 0.061978f, 0.469190f}, {0.284951f, 0.063168f, 0.472451f},
    {0.291366f, 0.064553f, 0.475462f}, {0.297740f, 0.066117f, 0.478243f},
    {0.304081f, 0.067835f, 0.480812f}, {0.310382f, 0.069702f, 0.483186f},
    {0.316654f, 0.071690f, 0.485380f}, {0.322899f, 0.073782f, 0.487408f},
    {0.329114f, 0.075972f, 0.489287f}, {0.335308f, 0.078236f, 0.491024f},
    {0.341482f, 0.080564f, 0.492631f}, {0.347636f, 0.082946f, 0.494121f},
    {0.353773f, 0.085373f, 0.495501f}, {0.359898f, 0.087831f, 0.496778f},
    {0.366012f, 0.090314f, 0.497960f}, {0.372116f, 0.092816f, 0.499053f},
    {0.378211f, 0.095332f, 0.500067f}, {0.384299f, 0.097855f, 0.501002f},
    {0.390384f, 0.100379f, 0.501864f}, {0.396467f, 0.102902f, 0.502658f},
    {0.402548f, 0.105420f, 0.503386f}, {0.408629f, 0.107930f, 0.504052f},
    {0.414709f, 0.110431f, 0.504662f}, {0.420791f, 0.112920f, 0.505215f},
    {0.426877f, 0.115395f, 0.505714f}, {0.432967f, 0.117855f, 0.506160f},
    {0.439062f, 0.120298f, 0.506555f}, {0.445163f, 0.122724f, 0.506901f},
    {0.451271f, 0.125132f, 0.507198f}, {0.457386f, 0.127522f, 0.507448f},
    {0.463508f, 0.129893f, 0.507652f}, {0.469640f, 0.132245f, 0.507809f},
    {0.475780f, 0.134577f, 0.507921f}, {0.481929f, 0.136891f, 0.507989f},
    {0.488088f, 0.139186f, 0.508011f}, {0.494258f, 0.141462f, 0.507988f},
    {0.500438f, 0.143719f, 0.507920f}, {0.506629f, 0.145958f, 0.507806f},
    {0.512831f, 0.148179f, 0.507648f}, {0.519045f, 0.150383f, 0.507443f},
    {0.525270f, 0.152569f, 0.507192f}, {0.531507f, 0.154739f, 0.506895f},
    {0.537755f, 0.156894f, 0.506551f}, {0.544015f, 0.159033f, 0.506159f},
    {0.550287f, 0.161158f, 0.505719f}, {0.556571f, 0.163269f, 0.505230f},
    {0.562866f, 0.165368f, 0.504692f}, {0.569172f, 0.167454f, 0.504105f},
    {0.575490f, 0.169530f, 0.503466f}, {0.581819f, 0.171596f, 0.502777f},
    {0.588158f, 0.173652f, 0.502035f}, {0.594508f, 0.175701f, 0.501241f},
    {0.600868f, 0.177743f, 0.500394f}, {0.607238f, 0.179779f, 0.499492f},
    {0.613617f, 0.181811f, 0.498536f}, {0.620005f, 0.183840f, 0.497524f},
    {0.626401f, 0.185867f, 0.496456f}, {0.632805f, 0.187893f, 0.495332f},
    {0.639216f, 0.189921f, 0.494150f}, {0.645633f, 0.191952f, 0.492910f},
    {0.652056f, 0.193986f, 0.491611f}, {0.658483f, 0.196027f, 0.490253f},
    {0.664915f, 0.198075f, 0.488836f}, {0.671349f, 0.200133f, 0.487358f},
    {0.677786f, 0.202203f, 0.485819f}, {0.684224f, 0.204286f, 0.484219f},
    {0.690661f, 0.206384f, 0.482558f}, {0.697098f, 0.208501f, 0.480835f},
    {0.703532f, 0.210638f, 0.479049f}, {0.709962f, 0.212797f, 0.477201f},
    {0.716387f, 0.214982f, 0.475290f}, {0.722805f, 0.217194f, 0.473316f},
    {0.729216f, 0.219437f, 0.471279f}, {0.735616f, 0.221713f, 0.469180f},
    {0.742004f, 0.224025f, 0.467018f}, {0.748378f, 0.226377f, 0.464794f},
    {0.754737f, 0.228772f, 0.462509f}, {0.761077f, 0.231214f, 0.460162f},
    {0.767398f, 0.233705f, 0.457755f}, {0.773695f, 0.236249f, 0.455289f},
    {0.779968f, 0.238851f, 0.452765f}, {0.786212f, 0.241514f, 0.450184f},
    {0.792427f, 0.244242f, 0.447543f}, {0.798608f, 0.247040f, 0.444848f},
    {0.804752f, 0.249911f, 0.442102f}, {0.810855f, 0.252861f, 0.439305f},
    {0.816914f, 0.255895f, 0.436461f}, {0.822926f, 0.259016f, 0.433573f},
    {0.828886f, 0.262229f, 0.430644f}, {0.834791f, 0.265540f, 0.427671f},
    {0.840636f, 0.268953f, 0.424666f}, {0.846416f, 0.272473f, 0.421631f},
    {0.852126f, 0.276106f, 0.418573f}, {0.857763f, 0.279857f, 0.415496f},
    {0.863320f, 0.283729f, 0.412403f}, {0.868793f, 0.287728f, 0.409303f},
    {0.874176f, 0.291859f, 0.406205f}, {0.879464f, 0.296125f, 0.403118f},
    {0.884651f, 0.300530f, 0.400047f}, {0.889731f, 0.305079f, 0.397002f},
    {0.894700f, 0.309773f, 0.393995f}, {0.899552f, 0.314616f, 0.391037f},
    {0.904281f, 0.319610f, 0.388137f}, {0.908884f, 0.324755f, 0.385308f},
    {0.913354f, 0.330052f, 0.382563f}, {0.917689f, 0.335500f, 0.379915f},
    {0.921884f, 0.341098f, 0.377376f}, {0.925937f, 0.346844f, 0.374959f},
    {0.929845f, 0.352734f, 0.372677f}, {0.933606f, 0.358764f, 0.370541f},
    {0.937221f, 0.364929f, 0.368567f}, {0.940687f, 0.371224f, 0.366762f},
    {0.944006f, 0.377643f, 0.365136f}, {0.947180f, 0.384178f, 0.363701f},
    {0.950210f, 0.390820f, 0.362468f}, {0.953099f, 0.397563f, 0.361438f},
    {0.955849f, 0.404400f, 0.360619f}, {0.958464f, 0.411324f, 0.360014f},
    {0.960949f, 0.418323f, 0.359630f}, {0.963310f, 0.425390f, 0.359469f},
    {0.965549f, 0.432519f, 0.359529f}, {0.967671f, 0.439703f, 0.359810f},
    {0.969680f, 0.446936f, 0.360311f}, {0.971582f, 0.454210f, 0.361030f},
    {0.973381f, 0.461520f, 0.361965f}, {0.975082f, 0.468861f, 0.363111f},
    {0.976690f, 0.476226f, 0.364466f}, {0.978210f, 0.483612f, 0.366025f},
    {0.979645f, 0.491014f, 0.367783f}, {0.981000f, 0.498428f, 0.369734f},
    {0.982279f, 0.505851f, 0.371874f}, {0.983485f, 0.513280f, 0.374198f},
    {0.984622f, 0.520713f, 0.376698f}, {0.985693f, 0.528148f, 0.379371f},
    {0.986700f, 0.535582f, 0.382210f}, {0.987646f, 0.543015f, 0.385210f},
    {0.988533f, 0.550446f, 0.388365f}, {0.989363f, 0.557873f, 0.391671f},
    {0.990138f, 0.565296f, 0.395122f}, {0.990871f, 0.572706f, 0.398714f},
    {0.991558f, 0.580107f, 0.402441f}, {0.992196f, 0.587502f, 0.406299f},
    {0.992785f, 0.594891f, 0.410283f}, {0.993326f, 0.602275f, 0.414390f},
    {0.993834f, 0.609644f, 0.418613f}, {0.994309f, 0.616999f, 0.422950f},
    {0.994738f, 0.624350f, 0.427397f}, {0.995122f, 0.631696f, 0.431951f},
    {0.995480f, 0.639027f, 0.436607f}, {0.995810f, 0.646344f, 0.441361f},
    {0.996096f, 0.653659f, 0.446213f}, {0.996341f, 0.660969f, 0.451160f},
    {0.996580f, 0.668256f, 0.456192f}, {0.996775f, 0.675541f, 0.461314f},
    {0.996925f, 0.682828f, 0.466526f}, {0.997077f, 0.690088f, 0.471811f},
    {0.997186f, 0.697349f, 0.477182f}, {0.997254f, 0.704611f, 0.482635f},
    {0.997325f, 0.711848f, 0.488154f}, {0.997351f, 0.719089f, 0.493755f},
    {0.997351f, 0.726324f, 0.499428f}, {0.997341f, 0.733545f, 0.505167f},
    {0.997285f, 0.740772f, 0.510983f}, {0.997228f, 0.747981f, 0.516859f},
    {0.997138f, 0.755190f, 0.522806f}, {0.997019f, 0.762398f, 0.528821f},
    {0.996898f, 0.769591f, 0.534892f}, {0.996727f, 0.776795f, 0.541039f},
    {0.996571f, 0.783977f, 0.547233f}, {0.996369f, 0.791167f, 0.553499f},
    {0.996162f, 0.798348f, 0.559820f}, {0.995932f, 0.805527f, 0.566202f},
    {0.995680f, 0.812706f, 0.572645f}, {0.995424f, 0.819875f, 0.579140f},
    {0.995131f, 0.827052f, 0.585701f}, {0.994851f, 0.834213f, 0.592307f},
    {0.994524f, 0.841387f, 0.598983f}, {0.994222f, 0.848540f, 0.605696f},
    {0.993866f, 0.855711f, 0.612482f}, {0.993545f, 0.862859f, 0.619299f},
    {0.993170f, 0.870024f, 0.626189f}, {0.992831f, 0.877168f, 0.633109f},
    {0.992440f, 0.884330f, 0.640099f}, {0.992089f, 0.891470f, 0.647116f},
    {0.991688f, 0.898627f, 0.654202f}, {0.991332f, 0.905763f, 0.661309f},
    {0.990930f, 0.912915f, 0.668481f}, {0.990570f, 0.920049f, 0.675675f},
    {0.990175f, 0.927196f, 0.682926f}, {0.989815f, 0.934329f, 0.690198f},
    {0.989434f, 0.941470f, 0.697519f}, {0.989077f, 0.948604f, 0.704863f},
    {0.988717f, 0.955742f, 0.712242f}, {0.988367f, 0.962878f, 0.719649f},
    {0.988033f, 0.970012f, 0.727077f}, {0.987691f, 0.977154f, 0.734536f},
    {0.987387f, 0.984288f, 0.742002f}, {0.987053f, 0.991438f, 0.749504f},
};

}  // namespace

Image magmaHeatmap(const Image& errorMap) {
  Image heatmap(errorMap.width, errorMap.height, 3);
  for (std::size_t i = 0; i < errorMap.pixelCount(); ++i) {
    const float v = errorMap.pixels[i * errorMap.channels];
    const float e = v > 0.0f ? std::min(v, 1.0f) : 0.0f;  // NaN as 0
    const float* color = kMagma[static_cast<int>(e * 255.0f + 0.5f)];
    std::copy(color, color + 3, &heatmap.pixels[i * 3]);
  }
  return heatmap;
}

}  // namespace dn::flip
