// The from-scratch diffusion experiment behind the Denoiser
// (dn/infer/scratch_diffusion.h): sampling defaults adapted to the
// input's sample count, and autoexposure.
#include "doctest_torch.h"
#include "tiny_models.h"

#include <ATen/CPUGeneratorImpl.h>

#include <cmath>

#include "dn/infer/denoiser.h"
#include "dn/infer/scratch_diffusion.h"

using namespace dn;

namespace {

ModelInfo tinyInfo() {
  ModelInfo info;
  info.base = tinyUNetConfig();
  info.has_control = true;
  info.control = ControlConfig{6, 3, 8, 2};  // albedo + diffuse_direct
  info.input_buffers = {"albedo", "diffuse_direct"};
  info.respacing = "27";
  info.notes["default_skip"] = "18";
  return info;
}

// Forward noise of the first executed step, in image units.
double startNoise(const NoiseSchedule& schedule, int64_t skip) {
  const double ab = schedule.alphaBar(startStep(schedule, skip));
  return std::sqrt((1.0 - ab) / ab);
}

Image randomImage(int w, int h, int c, double scale, uint64_t seed) {
  auto generator = at::detail::createCPUGenerator(seed);
  return tensorToImage(torch::rand({1, c, h, w}, generator, torch::kFloat) * scale);
}

}  // namespace

TEST_CASE("default skip and mean matching radius follow the input's noise level") {
  ModelInfo info = tinyInfo();
  info.notes["default_spp"] = "4";
  const NoiseSchedule schedule = info.samplingSchedule();
  const ScratchSampling defaults;
  const double anchor = startNoise(schedule, 18);

  for (int unknownOrAnchor : {0, 4}) {
    const auto plan = planSampling(info, schedule, defaults, unknownOrAnchor);
    CHECK(plan.skip == 18);
    CHECK(plan.meanMatchSigma == kDefaultMeanMatchSigma);
  }
  // 4x the samples: half the noise. The start is the last step whose forward
  // noise still covers it, and the radius halves.
  const auto p16 = planSampling(info, schedule, defaults, 16);
  CHECK(p16.spp == 16);
  CHECK(p16.noiseScale == doctest::Approx(0.5));
  CHECK(p16.meanMatchSigma == doctest::Approx(1.0));
  CHECK(startNoise(schedule, p16.skip) >= 0.5 * anchor);
  CHECK(startNoise(schedule, p16.skip + 1) < 0.5 * anchor);
  const auto p64 = planSampling(info, schedule, defaults, 64);
  CHECK(p64.skip > p16.skip);
  CHECK(p64.meanMatchSigma == doctest::Approx(0.5));
  const auto p1 = planSampling(info, schedule, defaults, 1);
  CHECK(p1.skip < 18);
  CHECK(p1.meanMatchSigma == doctest::Approx(4.0));

  // --spp beats the file; explicit skip and radius beat the adaptation.
  ScratchSampling explicitOptions;
  explicitOptions.spp = 64;
  CHECK(planSampling(info, schedule, explicitOptions, 4).skip == p64.skip);
  explicitOptions.skip = 5;
  explicitOptions.meanMatchSigma = 0.0;
  const auto fixed = planSampling(info, schedule, explicitOptions, 4);
  CHECK(fixed.skip == 5);
  CHECK(fixed.meanMatchSigma == 0.0);

  // Another step count keeps the default's noise level, not its step count.
  const NoiseSchedule fine = respace(info.trainingSchedule(), "100");
  const auto onFine = planSampling(info, fine, defaults, 0);
  CHECK(startNoise(fine, onFine.skip) >= anchor * (1 - 1e-9));
  CHECK(startNoise(fine, onFine.skip + 1) < anchor);

  // A model without default_spp: no adaptation.
  info.notes.erase("default_spp");
  CHECK(planSampling(info, schedule, defaults, 64).skip == 18);
  CHECK(planSampling(info, schedule, defaults, 64).meanMatchSigma == kDefaultMeanMatchSigma);
}

TEST_CASE("a measured noise level wins over the sample count when the model has a reference") {
  ModelInfo info = tinyInfo();
  info.notes["default_spp"] = "4";
  info.notes["noise_reference"] = "0.2";
  const NoiseSchedule schedule = info.samplingSchedule();
  const ScratchSampling defaults;
  const double anchor = startNoise(schedule, 18);

  // As noisy as the reference: the defaults, whatever the file's count says.
  const auto same = planSampling(info, schedule, defaults, 64, 0.2);
  CHECK(same.skip == 18);
  CHECK(same.noiseScale == doctest::Approx(1.0));
  CHECK(same.meanMatchSigma == doctest::Approx(kDefaultMeanMatchSigma));
  CHECK(same.spp == 64);  // still known (black regions use it)
  // Half the noise: the same plan as 4x the samples.
  const auto half = planSampling(info, schedule, defaults, 4, 0.1);
  CHECK(half.noiseScale == doctest::Approx(0.5));
  CHECK(half.skip == planSampling(info, schedule, defaults, 16).skip);
  CHECK(half.meanMatchSigma == doctest::Approx(1.0));
  // Twice the noise: an earlier start that still covers it, a wider radius.
  const auto twice = planSampling(info, schedule, defaults, 4, 0.4);
  CHECK(twice.skip < 18);
  CHECK(startNoise(schedule, twice.skip) >= 2.0 * anchor);
  CHECK(twice.meanMatchSigma == doctest::Approx(4.0));
  // Bounded: no start from pure noise, no zero radius.
  CHECK(planSampling(info, schedule, defaults, 4, 100.0).noiseScale == kMaxNoiseScale);
  CHECK(planSampling(info, schedule, defaults, 4, 0.0).noiseScale == kMinNoiseScale);

  // --spp is the user's word: the sample count decides, not the measurement.
  ScratchSampling withSpp;
  withSpp.spp = 16;
  CHECK(planSampling(info, schedule, withSpp, 4, 0.4).noiseScale == doctest::Approx(0.5));
  // Not measured, or no reference in the model: the sample count decides.
  CHECK(planSampling(info, schedule, defaults, 16).noiseScale == doctest::Approx(0.5));
  info.notes.erase("noise_reference");
  CHECK(planSampling(info, schedule, defaults, 16, 0.4).noiseScale == doctest::Approx(0.5));
}

TEST_CASE("denoise measures the render's noise only when the model has a reference") {
  torch::manual_seed(5);
  ModelInfo info = tinyInfo();
  LoadedModel loaded{info, buildDenoiser(info)};
  FrameBuffers frame;
  frame.width = frame.height = 16;
  frame.buffers["color"] = randomImage(16, 16, 3, 0.5, 4);
  frame.buffers["albedo"] = randomImage(16, 16, 3, 1.0, 5);
  frame.buffers["diffuse_direct"] = randomImage(16, 16, 3, 0.2, 6);
  CHECK(Denoiser(loaded).denoise(frame, {}).plan->noise == -1.0);

  loaded.info.notes["noise_reference"] = "0.2";
  const Denoiser denoiser(loaded);
  const auto result = denoiser.denoise(frame, {});
  CHECK(result.plan->noise > 0.0);
  CHECK(result.plan->noise == doctest::Approx(denoiser.measureNoise(frame)));
  CHECK(result.plan->noiseScale == doctest::Approx(result.plan->noise / 0.2));
  // Measured at the model's exposure: a forced exposure leaves the plan as it is.
  DenoiseOptions forced;
  forced.exposure = 3.0;
  const auto exposed = denoiser.denoise(frame, forced);
  CHECK(exposed.exposure == 3.0);
  CHECK(exposed.plan->noise == result.plan->noise);
  CHECK(exposed.plan->skip == result.plan->skip);
}

TEST_CASE("autoexposure: a brighter render gives the same result, brighter") {
  torch::manual_seed(3);
  ModelInfo info = tinyInfo();
  info.notes["exposure_target"] = "0.3";
  LoadedModel loaded{info, buildDenoiser(info)};
  // Random weights everywhere, also in the zero-initialised control outputs,
  // so the aux radiance scaling is exercised too.
  randomize(*loaded.model, 11, 0.05);
  const Denoiser denoiser(loaded);

  FrameBuffers dim, bright;
  dim.width = bright.width = 16;
  dim.height = bright.height = 16;
  dim.buffers["color"] = randomImage(16, 16, 3, 0.05, 1);
  dim.buffers["albedo"] = bright.buffers["albedo"] = randomImage(16, 16, 3, 1.0, 2);
  dim.buffers["diffuse_direct"] = randomImage(16, 16, 3, 0.02, 3);
  for (const char* name : {"color", "diffuse_direct"}) {
    bright.buffers[name] = dim.buffers[name];
    for (float& v : bright.buffers[name].pixels) v *= 8.0f;
  }
  DenoiseOptions options;
  options.seed = 7;
  auto relativeGap = [](const DenoiseResult& a, const DenoiseResult& b, double factor) {
    const auto ta = imageToTensor(a.color), tb = imageToTensor(b.color) / factor;
    return ((ta - tb).abs() / (ta.abs() + 1e-3)).max().item<double>();
  };

  const auto a = denoiser.denoise(dim, options), b = denoiser.denoise(bright, options);
  CHECK(a.exposure == doctest::Approx(8.0 * b.exposure).epsilon(1e-6));
  CHECK(a.exposure > 1.0);  // a dark frame is brightened
  CHECK(relativeGap(a, b, 8.0) < 1e-3);

  // Without it the model sees two different images (so the check above can fail).
  options.exposure = 1.0;
  const auto c = denoiser.denoise(dim, options), d = denoiser.denoise(bright, options);
  CHECK(c.exposure == 1.0);
  CHECK(relativeGap(c, d, 8.0) > 1e-2);
}
