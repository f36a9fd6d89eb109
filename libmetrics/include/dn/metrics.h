// Image-quality metrics for HDR renders, computed on the first three channels.
// Conventions follow the paper: L1 and MSE on radiance clamped to [0, 6];
// PSNR and SSIM on Reinhard-tonemapped images clipped to [0, 1].
#pragma once

#include <map>
#include <string>
#include <vector>

#include "dn/image.h"

namespace dn::metrics {

constexpr float kRelMseEpsilon = 1e-2f;  // relMSE = (x - y)^2 / (y^2 + eps)
constexpr float kSmapeEpsilon = 1e-2f;

double l1(const Image& reference, const Image& test);      // mean |x - y| on clamp(., 0, 6)
double mse(const Image& reference, const Image& test);     // mean (x - y)^2 on clamp(., 0, 6)
double relMse(const Image& reference, const Image& test);  // on non-negative linear radiance
double psnr(const Image& reference, const Image& test);    // dB, Reinhard, peak 1
double ssim(const Image& reference, const Image& test);    // Reinhard, 11x11 Gaussian, sigma 1.5
// Paper's SMAPE over whole images: |A - B|_1 / (|A|_1 + |B|_1 + eps), on clamp(., 0, 6),
// with |.|_1 the mean absolute value (as the SMAPE training loss), so eps is size-independent.
double smape(const Image& reference, const Image& test);

// Temporal flicker of the error between two consecutive frames: the mean over
// pixels and channels of |e_t - e_(t-1)|, e = R(test) - R(reference) with R
// Reinhard's tonemap clipped to [0, 1] (as PSNR sees images). With one shared
// reference (a locked-off shot) it is the mean |R(test_t) - R(test_(t-1))|.
double flicker(const Image& previousReference, const Image& previousTest, const Image& reference,
               const Image& test);

// Reinhard tonemap then sRGB encoding: the LDR image LDR-FLIP and previews see.
Image reinhardSrgb(const Image& linear);

// Every metric dnmetrics knows, in its output order.
const std::vector<std::string>& metricNames();
bool isMetricName(const std::string& name);
// Whether larger is better (psnr, ssim) or worse (errors).
bool higherIsBetter(const std::string& name);

struct Comparison {
  std::map<std::string, double> values;  // metric name -> value
  Image flipMap;                         // LDR-FLIP error map when "flip" was asked for
  Image hdrFlipMap;                      // HDR-FLIP error map when "hdrflip" was asked for
};

// Computes the named metrics. Both images must have the same size and >= 3
// channels, and hold finite values (the caller counts and reports NaN/Inf).
// Throws std::invalid_argument on a shape mismatch or an unknown name.
Comparison compare(const Image& reference, const Image& test,
                   const std::vector<std::string>& names);

}  // namespace dn::metrics
