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

std::vector<std::string> featureBuffers(const FrameBuffers& frame) {
  std::vector<std::string> features;
  for (const auto& name : noiseFeatureBuffers())
    if (frame.has(name)) features.push_back(name);
  return features;
}

// 1 where no feature buffer has an edge or texture, for rows [y0, y0 + rows)
// less the first and last (the valid pixels of highPass).
torch::Tensor flatPixels(const FrameBuffers& frame, const std::vector<std::string>& features,
                         int64_t y0, int64_t rows) {
  // The normalization needs a curve only for radiance buffers, which these are not.
  const auto guide =
      normalizedAuxRegion(frame, features, tonemap::Curve::Log, y0, 0, rows, frame.width, 1.0);
  const auto edge = std::get<0>(highPass(guide).abs().max(1, true));
  return (edge < kFeatureEdge).to(torch::kFloat32);
}

}  // namespace

const std::vector<std::string>& noiseFeatureBuffers() {
  static const std::vector<std::string> names = {"albedo", "normal", "depth"};
  return names;
}

NoiseLeft measureNoiseLeft(const torch::Tensor& input, const torch::Tensor& output,
                           const FrameBuffers& frame) {
  torch::NoGradGuard noGrad;
  const std::vector<std::string> features = featureBuffers(frame);
  const int64_t height = input.size(2), width = input.size(3);
  if (height < 3 || width < 3) return {};
  NoiseLeft flat, all;
  double flatCount = 0, allCount = 0;
  for (int64_t y0 = 0; y0 + 2 < height; y0 += kStripRows) {
    const int64_t rows = std::min(kStripRows + 2, height - y0);
    // Single precision per pixel (a ratio of sums is wanted), double sums.
    const auto in = highPass(input.narrow(2, y0, rows).to(torch::kFloat32)).square_();
    const auto out = highPass(output.narrow(2, y0, rows).to(torch::kFloat32)).square_();
    all.input += in.sum(torch::kFloat64).item<double>();
    all.output += out.sum(torch::kFloat64).item<double>();
    allCount += double(in.size(2) * in.size(3));
    if (features.empty()) continue;
    const auto mask = flatPixels(frame, features, y0, rows);
    flat.input += (in * mask).sum(torch::kFloat64).item<double>();
    flat.output += (out * mask).sum(torch::kFloat64).item<double>();
    flatCount += mask.sum(torch::kFloat64).item<double>();
  }
  NoiseLeft left = flatCount >= kMinMaskedFraction * allCount ? flat : all;
  left.input = std::sqrt(left.input);
  left.output = std::sqrt(left.output);
  return left;
}

bool correlatedNoiseLeft(const NoiseLeft& left) {
  return left.input > 0 && left.output > kCorrelatedNoiseLeft * left.input;
}

double estimateNoise(const torch::Tensor& image, const FrameBuffers& frame) {
  torch::NoGradGuard noGrad;
  const std::vector<std::string> features = featureBuffers(frame);
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
    const auto flat = flatPixels(frame, features, y0, rows);
    maskedSum += (squared * flat).sum().item<double>();
    maskedCount += flat.sum().item<int64_t>() * image.size(1);
  }
  if (allCount == 0) return 0.0;
  if (maskedCount >= kMinMaskedFraction * allCount) return std::sqrt(maskedSum / maskedCount);
  return std::sqrt(allSum / allCount);
}

}  // namespace dn
