// FLIP image difference evaluator (Andersson et al., HPG 2020) and HDR-FLIP
// (Andersson et al., EG 2021), written to agree with NVIDIA's flip-evaluator.
//
// LDR-FLIP filters both images with contrast sensitivity functions in YCxCz,
// compares colors with HyAB in Hunt-adjusted L*a*b*, compares edges and points
// found with Gaussian-derivative filters, and combines the two per pixel.
// HDR-FLIP tonemaps both images at a range of exposures and keeps, per pixel,
// the largest LDR-FLIP error. Error maps have one channel with values in [0,1].
// Work is spread over rows on dn::kernelThreadCount() threads (dn/parallel.h).
#pragma once

#include <optional>

#include "dn/image.h"

namespace dn::flip {

// Viewer 0.7 m from a 0.7 m wide, 3840 pixel wide display (the reference's default).
constexpr double kDefaultPixelsPerDegree = 0.7 * (3840.0 / 0.7) * (3.14159265358979 / 180.0);

enum class Tonemapper { Aces, Hable, Reinhard };

struct HdrOptions {
  double pixelsPerDegree = kDefaultPixelsPerDegree;
  // Unset values are derived from the reference image as in HDR-FLIP: the
  // range runs from the exposure that maps the brightest luminance to 0.85
  // after tonemapping to the exposure that does so for the median luminance.
  std::optional<double> startExposure;
  std::optional<double> stopExposure;
  std::optional<int> numExposures;  // >= 1; default max(2, ceil(stop - start))
  Tonemapper tonemapper = Tonemapper::Aces;
};

struct ExposureRange {
  double start = 0.0;
  double stop = 0.0;
  int count = 2;
};

// The exposures hdrErrorMap() will use for this reference and these options.
// As in flip-evaluator 1.7 the median luminance is floored at float epsilon;
// an all-black reference (which the reference rejects) gives the range [0, 0].
ExposureRange exposureRange(const Image& referenceLinear, const HdrOptions& options = {});

// Inputs are sRGB-encoded with values in [0,1] (others are clamped), at least
// 3 channels of which the first 3 are used, same size. Throws
// std::invalid_argument on mismatched or unusable inputs.
Image ldrErrorMap(const Image& referenceSrgb, const Image& testSrgb,
                  double pixelsPerDegree = kDefaultPixelsPerDegree);

// Inputs are linear RGB radiance (negative values count as 0; NaN or infinite
// values throw std::invalid_argument).
Image hdrErrorMap(const Image& referenceLinear, const Image& testLinear,
                  const HdrOptions& options = {});

struct Stats {
  double mean = 0.0;
  // Percentiles of the error weighted by itself, i.e. of where the error mass
  // lies (the FLIP tool's "weighted median" and "weighted quartiles").
  double weightedMedian = 0.0;
  double weightedQuartile1 = 0.0;
  double weightedQuartile3 = 0.0;
  // Plain percentiles, linearly interpolated between sorted values.
  double p25 = 0.0, p50 = 0.0, p75 = 0.0, p95 = 0.0, p99 = 0.0;
  double min = 0.0;
  double max = 0.0;
};

// Statistics of channel 0 of an error map. Throws std::invalid_argument if empty.
Stats statistics(const Image& errorMap);

// The magma colormap as the reference applies it: 256 entries, nearest entry,
// sRGB-encoded RGB in [0,1]. Uses channel 0 of the error map.
Image magmaHeatmap(const Image& errorMap);

}  // namespace dn::flip
