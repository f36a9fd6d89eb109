#include "dn/infer/noise_estimate.h"

#include <algorithm>
#include <cmath>

#include "dn/nn/model_inputs.h"
#include "dn/tonemap.h"

namespace dn {

const std::vector<std::string>& noiseFeatureBuffers() {
  static const std::vector<std::string> names = {"albedo", "normal", "depth"};
  return names;
}

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

// Immerkaer's residual at x of three consecutive rows, as highPass gives it.
inline float residual(const float* up, const float* mid, const float* down, int64_t x) {
  const float a = up[x - 1] - 2 * up[x] + up[x + 1];
  const float b = mid[x - 1] - 2 * mid[x] + mid[x + 1];
  const float c = down[x - 1] - 2 * down[x] + down[x + 1];
  return (a - 2 * b + c) / 6.0f;
}

struct NoiseSums {
  double allInput = 0, allOutput = 0, flatInput = 0, flatOutput = 0, flatPixels = 0;
};

// The high-pass energy of input and output over interior rows [y0, y1); pixels
// where a feature has an edge count only in the `all` sums. The images are
// planes of one row-major (C, height, width) block each; `guide` has
// `guideChannels` planes (none: no features).
NoiseSums noiseSums(const float* input, const float* output, int64_t channels, const float* guide,
                    int64_t guideChannels, int64_t height, int64_t width, int64_t y0, int64_t y1) {
  const int64_t plane = height * width;
  NoiseSums sums;
  for (int64_t y = y0; y < y1; ++y)
    for (int64_t x = 1; x + 1 < width; ++x) {
      double in = 0, out = 0;
      for (int64_t c = 0; c < channels; ++c) {
        const float* i = input + c * plane + (y - 1) * width;
        const float* o = output + c * plane + (y - 1) * width;
        const float ri = residual(i, i + width, i + 2 * width, x);
        const float ro = residual(o, o + width, o + 2 * width, x);
        in += ri * ri;
        out += ro * ro;
      }
      sums.allInput += in;
      sums.allOutput += out;
      if (guideChannels == 0) continue;
      float edge = 0;
      for (int64_t g = 0; g < guideChannels; ++g) {
        const float* r = guide + g * plane + (y - 1) * width;
        edge = std::max(edge, std::abs(residual(r, r + width, r + 2 * width, x)));
      }
      if (edge < static_cast<float>(kFeatureEdge)) {
        sums.flatInput += in;
        sums.flatOutput += out;
        sums.flatPixels += 1;
      }
    }
  return sums;
}

}  // namespace

NoiseLeft measureNoiseLeftByTensors(const torch::Tensor& input, const torch::Tensor& output,
                                    const FrameBuffers& frame) {
  FrameUploads uploads(frame, input.device());
  return measureNoiseLeftByTensors(input, output, uploads);
}

NoiseLeft measureNoiseLeftByTensors(const torch::Tensor& input, const torch::Tensor& output,
                                    FrameUploads& frame) {
  if (input.size(2) < 3 || input.size(3) < 3) return {};
  const std::vector<std::string> features = featureBuffers(frame.frame());
  const torch::Tensor in = highPass(input.to(torch::kFloat32)).square().sum(1).to(torch::kDouble);
  const torch::Tensor out = highPass(output.to(torch::kFloat32)).square().sum(1).to(torch::kDouble);
  torch::Tensor flat = torch::zeros_like(in);
  if (!features.empty()) {
    std::vector<torch::Tensor> parts;
    for (const auto& name : features) parts.push_back(frame.stored(name));
    const torch::Tensor guide = normalizeAux(torch::cat(parts, 1), features, tonemap::Curve::Log);
    const torch::Tensor edge = std::get<0>(highPass(guide).abs().max(1));
    flat = (edge < kFeatureEdge).to(torch::kDouble);
  }
  const torch::Tensor sums =
      torch::stack({in.sum(), out.sum(), (in * flat).sum(), (out * flat).sum(), flat.sum()}).cpu();
  const double* v = sums.data_ptr<double>();
  const double pixels = double(in.size(1)) * double(in.size(2));
  const bool useFlat = v[4] >= kMinMaskedFraction * pixels;
  NoiseLeft left;
  left.input = std::sqrt(useFlat ? v[2] : v[0]);
  left.output = std::sqrt(useFlat ? v[3] : v[1]);
  return left;
}

NoiseLeft measureNoiseLeft(const torch::Tensor& input, const torch::Tensor& output,
                           FrameUploads& frame) {
  if (!input.is_cpu()) return measureNoiseLeftByTensors(input, output, frame);
  return measureNoiseLeft(input, output, frame.frame());
}

NoiseLeft measureNoiseLeft(const torch::Tensor& input, const torch::Tensor& output,
                           const FrameBuffers& frame) {
  if (!input.is_cpu()) return measureNoiseLeftByTensors(input, output, frame);
  const std::vector<std::string> features = featureBuffers(frame);
  const torch::Tensor in = input.to(torch::kFloat32).contiguous();
  const torch::Tensor out = output.to(torch::kFloat32).contiguous();
  const int64_t channels = in.size(1), height = in.size(2), width = in.size(3);
  if (height < 3 || width < 3) return {};
  // The features as the model sees them (one pass over the frame, vectorized).
  const torch::Tensor guide =
      features.empty()
          ? torch::Tensor()
          : normalizedAuxRegion(frame, features, tonemap::Curve::Log, 0, 0, height, width, 1.0)
                .contiguous();
  // Blocks of rows in parallel, each with its own sums.
  constexpr int64_t kBlockRows = 16;
  const int64_t blocks = (height - 2 + kBlockRows - 1) / kBlockRows;
  std::vector<NoiseSums> parts(static_cast<std::size_t>(blocks));
  at::parallel_for(0, blocks, 1, [&](int64_t first, int64_t last) {
    for (int64_t b = first; b < last; ++b)
      parts[b] = noiseSums(in.data_ptr<float>(), out.data_ptr<float>(), channels,
                           guide.defined() ? guide.data_ptr<float>() : nullptr,
                           guide.defined() ? guide.size(1) : 0, height, width, 1 + b * kBlockRows,
                           std::min(height - 1, 1 + (b + 1) * kBlockRows));
  });
  NoiseSums sum;
  for (const auto& p : parts) {
    sum.allInput += p.allInput;
    sum.allOutput += p.allOutput;
    sum.flatInput += p.flatInput;
    sum.flatOutput += p.flatOutput;
    sum.flatPixels += p.flatPixels;
  }
  const double pixels = double(height - 2) * double(width - 2);
  const bool flat = sum.flatPixels >= kMinMaskedFraction * pixels;
  NoiseLeft left;
  left.input = std::sqrt(flat ? sum.flatInput : sum.allInput);
  left.output = std::sqrt(flat ? sum.flatOutput : sum.allOutput);
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
