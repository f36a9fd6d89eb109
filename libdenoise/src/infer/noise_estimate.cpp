#include "dn/infer/noise_estimate.h"

#include <algorithm>
#include <cmath>

#include "dn/infer/model_inputs.h"
#include "dn/tonemap.h"

namespace dn {

namespace {

constexpr int64_t kStripRows = 256;
constexpr double kMinMaskedFraction = 0.05;

// Immerkaer's operator (second differences in x, y and both) per channel,
// divided by 6 = its L2 norm: unit gain on independent noise. Valid pixels only.
torch::Tensor highPass(const torch::Tensor& x) {
  namespace F = torch::nn::functional;
  const auto kernel = torch::tensor({1.0, -2.0, 1.0, -2.0, 4.0, -2.0, 1.0, -2.0, 1.0}, x.options())
                          .view({1, 1, 3, 3}) /
                      6.0;
  const int64_t c = x.size(1);
  return F::conv2d(x, kernel.expand({c, 1, 3, 3}), F::Conv2dFuncOptions().groups(c));
}

}  // namespace

double estimateNoise(const torch::Tensor& image, const FrameBuffers& frame) {
  torch::NoGradGuard noGrad;
  std::vector<std::string> features;
  for (const char* name : {"albedo", "normal", "depth"})
    if (frame.has(name)) features.push_back(name);
  const int64_t height = image.size(2);
  if (height < 3 || image.size(3) < 3) return 0.0;
  double maskedSum = 0.0, allSum = 0.0;
  int64_t maskedCount = 0, allCount = 0;
  // Strips overlap by two rows so every interior pixel is counted once.
  for (int64_t y0 = 0; y0 + 2 < height; y0 += kStripRows) {
    const int64_t rows = std::min(kStripRows + 2, height - y0);
    const auto squared = highPass(image.narrow(2, y0, rows).to(torch::kFloat64)).pow(2);
    allSum += squared.sum().item<double>();
    allCount += squared.numel();
    if (features.empty()) continue;
    // The normalization needs a curve only for radiance buffers, which these are not.
    const auto guide =
        normalizedAuxRegion(frame, features, tonemap::Curve::Log, y0, 0, rows, frame.width, 1.0);
    const auto edge = std::get<0>(highPass(guide).abs().max(1, true));
    const auto flat = (edge < kFeatureEdge).to(torch::kFloat64);
    maskedSum += (squared * flat).sum().item<double>();
    maskedCount += flat.sum().item<int64_t>() * image.size(1);
  }
  if (allCount == 0) return 0.0;
  if (maskedCount >= kMinMaskedFraction * allCount) return std::sqrt(maskedSum / maskedCount);
  return std::sqrt(allSum / allCount);
}

}  // namespace dn
