// The render's own noise level (dn/infer/noise_estimate.h), against noise of known
// standard deviation added to images with and without structure.
#include "doctest_torch.h"

#include <ATen/CPUGeneratorImpl.h>

#include "dn/infer/denoiser.h"
#include "dn/infer/noise_estimate.h"

using namespace dn;

namespace {

// A smooth image: a ramp in x and y, per channel.
torch::Tensor ramp(int64_t h, int64_t w) {
  auto y = torch::linspace(-0.5, 0.5, h).view({1, 1, h, 1});
  auto x = torch::linspace(-0.3, 0.4, w).view({1, 1, 1, w});
  return torch::cat({x + y, x - y, 0.5 * x + 0.2 * y}, 1).contiguous();
}

torch::Tensor gaussian(int64_t h, int64_t w, double std, uint64_t seed) {
  auto generator = at::detail::createCPUGenerator(seed);
  return torch::randn({1, 3, h, w}, generator, torch::kFloat) * std;
}

FrameBuffers frameWith(const torch::Tensor& albedo) {
  FrameBuffers frame;
  frame.height = static_cast<int>(albedo.size(2));
  frame.width = static_cast<int>(albedo.size(3));
  frame.buffers["albedo"] = tensorToImage(albedo);
  return frame;
}

}  // namespace

TEST_CASE("independent noise of a known level is measured on smooth and on tall frames") {
  const FrameBuffers none;                          // no features: every pixel counts
  CHECK(estimateNoise(ramp(64, 80), none) < 1e-5);  // a gradient has no noise
  for (double std : {0.01, 0.1, 0.3}) {
    CHECK(estimateNoise(ramp(64, 80) + gaussian(64, 80, std, 1), none) ==
          doctest::Approx(std).epsilon(0.05));
  }
  // Taller than one strip of rows: strips must neither drop nor repeat rows.
  CHECK(estimateNoise(ramp(600, 40) + gaussian(600, 40, 0.2, 2), none) ==
        doctest::Approx(0.2).epsilon(0.03));
  // Too small to measure.
  CHECK(estimateNoise(torch::rand({1, 3, 2, 2}), none) == 0.0);
}

TEST_CASE("texture that the feature buffers explain is not taken for noise") {
  // A noiseless image: flat on the left, a fine random texture on the right,
  // the same texture in the albedo. (Straight edges need no mask: the operator
  // does not see them.)
  auto texture = torch::full({1, 3, 48, 48}, 0.5);
  texture.narrow(3, 24, 24).copy_(0.5 + gaussian(48, 24, 0.2, 4));
  const FrameBuffers flatAlbedo = frameWith(torch::full({1, 3, 48, 48}, 0.5));
  const FrameBuffers texturedAlbedo = frameWith(texture.clone());
  CHECK(estimateNoise(texture, flatAlbedo) > 0.1);  // unexplained: looks like noise
  CHECK(estimateNoise(texture, texturedAlbedo) < 0.1 * estimateNoise(texture, flatAlbedo));

  // With noise on top, the masked estimate is the noise alone.
  const auto noisy = texture + gaussian(48, 48, 0.05, 3);
  CHECK(estimateNoise(noisy, texturedAlbedo) == doctest::Approx(0.05).epsilon(0.1));

  // Features with texture everywhere leave too little: every pixel counts.
  const FrameBuffers allTextured = frameWith(0.5 + gaussian(48, 48, 0.2, 5));
  CHECK(estimateNoise(noisy, allTextured) == doctest::Approx(estimateNoise(noisy, FrameBuffers{})));
}

TEST_CASE("the noise a denoiser leaves, as a fraction of its input's") {
  const FrameBuffers none;
  const auto clean = ramp(96, 96);
  // Independent noise, removed: nothing left.
  const auto noisy = clean + gaussian(96, 96, 0.1, 5);
  const NoiseLeft removed = measureNoiseLeft(noisy, clean, none);
  CHECK(removed.fraction() < 1e-3);
  CHECK_FALSE(correlatedNoiseLeft(removed));
  // Half of it removed.
  CHECK(measureNoiseLeft(noisy, clean + 0.5 * (noisy - clean), none).fraction() ==
        doctest::Approx(0.5).epsilon(1e-6));
  // Noise splatted over 2x2 pixels, left as it is: all of it, taken for correlated.
  const auto n = gaussian(97, 97, 0.1, 6);
  const auto splat = (n.narrow(2, 0, 96) + n.narrow(2, 1, 96)).narrow(3, 0, 96) +
                     (n.narrow(2, 0, 96) + n.narrow(2, 1, 96)).narrow(3, 1, 96);
  const NoiseLeft kept = measureNoiseLeft(clean + splat, clean + splat, none);
  CHECK(kept.fraction() == doctest::Approx(1.0));
  CHECK(correlatedNoiseLeft(kept));
  // Albedo textured everywhere: too few flat pixels, so every pixel counts.
  const FrameBuffers textured = frameWith(0.5 + gaussian(96, 96, 0.2, 7));
  CHECK(measureNoiseLeft(noisy, clean + 0.5 * (noisy - clean), textured).fraction() ==
        doctest::Approx(0.5).epsilon(1e-6));
  // Too small to measure.
  CHECK(measureNoiseLeft(torch::rand({1, 3, 2, 2}), torch::rand({1, 3, 2, 2}), none).fraction() ==
        0.0);
}

TEST_CASE("the noise left is measured where the features are flat, as a convolution gives it") {
  // Albedo flat on the left half, textured on the right; the output keeps a
  // fifth of the noise on the left and all of it on the right.
  const int64_t h = 70, w = 90;
  auto albedo = torch::full({1, 3, h, w}, 0.5);
  albedo.narrow(3, 45, 45).add_(gaussian(h, 45, 0.2, 9));
  const FrameBuffers frame = frameWith(albedo);
  const auto clean = ramp(h, w), noise = gaussian(h, w, 0.1, 10);
  auto left = torch::full({1, 1, 1, w}, 1.0);
  left.narrow(3, 45, 45).fill_(0.2);
  const auto input = clean + noise, output = clean + noise * (1.2 - left);
  // The reference: Immerkaer's kernel as a convolution, the albedo's edges masked.
  const auto kernel =
      torch::tensor({1.0, -2.0, 1.0, -2.0, 4.0, -2.0, 1.0, -2.0, 1.0}).view({1, 1, 3, 3}) / 6.0;
  auto highPass = [&](const torch::Tensor& x) {
    return torch::nn::functional::conv2d(x, kernel.expand({3, 1, 3, 3}).to(x.dtype()),
                                         torch::nn::functional::Conv2dFuncOptions().groups(3));
  };
  const torch::Tensor flat = std::get<0>(highPass(albedo).abs().max(1, true)) < kFeatureEdge;
  auto energy = [&](const torch::Tensor& x) {
    const torch::Tensor masked = highPass(x).square() * flat;
    return masked.sum().template item<double>();
  };
  const NoiseLeft measured = measureNoiseLeft(input, output, frame);
  CHECK(measured.fraction() ==
        doctest::Approx(std::sqrt(energy(output) / energy(input))).epsilon(1e-5));
  CHECK(measured.fraction() == doctest::Approx(0.2).epsilon(0.05));
}

TEST_CASE("the noise left measured by tensor operations (a GPU's way) agrees with the loops") {
  const int64_t h = 70, w = 90;
  auto albedo = torch::full({1, 3, h, w}, 0.5);
  albedo.narrow(3, 45, 45).add_(gaussian(h, 45, 0.2, 9));
  const FrameBuffers textured = frameWith(albedo);
  const auto clean = ramp(h, w), noise = gaussian(h, w, 0.1, 10);
  auto left = torch::full({1, 1, 1, w}, 1.0);
  left.narrow(3, 45, 45).fill_(0.2);
  const auto input = clean + noise, output = clean + noise * (1.2 - left);
  for (const FrameBuffers& frame : {textured, FrameBuffers()}) {
    const NoiseLeft loops = measureNoiseLeft(input, output, frame);
    const NoiseLeft tensors = measureNoiseLeftByTensors(input, output, frame);
    CHECK(tensors.input == doctest::Approx(loops.input).epsilon(1e-5));
    CHECK(tensors.output == doctest::Approx(loops.output).epsilon(1e-5));
  }
  // Only the flat left half counts, where the output keeps a fifth of the noise.
  const NoiseLeft flatOnly = measureNoiseLeftByTensors(input, output, textured);
  CHECK(flatOnly.fraction() == doctest::Approx(0.2).epsilon(0.05));
  CHECK(measureNoiseLeftByTensors(torch::rand({1, 3, 2, 2}), torch::rand({1, 3, 2, 2}),
                                  FrameBuffers())
            .fraction() == 0.0);
}
