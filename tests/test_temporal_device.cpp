// The temporal filter as tensor operations (dn/temporal/device_filter.h), run
// on LibTorch's CPU device, against filterFrame on the same windows: still
// and moving shots (a pan with sub-pixel motion, so Catmull-Rom, and an
// occluder that uncovers the background), relit, repeated-noise and
// changed-light neighbours, the learned trust, the past histories and the
// blend, and with OpenImageIO the Cycles renders of testdata/sequence. The
// tensor path computes in float32 where filterFrame computes in double: its
// images must agree within kMaxDifference and kMinPsnr, its decisions (the
// verdicts, the taps) exactly; where nothing is trusted it gives the frame's
// own result bit for bit.
#include "doctest_torch.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>

#include "dn/temporal/device_filter.h"
#include "dn/temporal/temporal_filter.h"
#ifdef DN_TEST_READS_EXR
#include "dn/io/buffer_io.h"
#endif

using namespace dn;
using namespace dn::temporal;

namespace {

// float32 against double (values here are 0.1-1.5; the frame counts up to 5):
// measured on the CPU device 6e-6 and 140 dB at worst.
constexpr double kMaxDifference = 2e-5;
constexpr double kMinPsnr = 120.0;

const torch::Device kCpu(torch::kCPU);

float texture(double x, double y) {
  return 0.3f + 0.2f * std::sin(0.7 * x) * std::cos(0.45 * y) + 0.1f * std::sin(0.13 * (x + 2 * y));
}

// A frame of a synthetic shot: a textured background (depth 10) shown shifted
// by `shift` px, and a square occluder (depth 2, flat) at x = boxX.
struct Scene {
  int width = 40, height = 28;
  double shift = 0.0;
  int boxX = -100, boxY = 8, boxSize = 0;
  bool inBox(int x, int y) const {
    return x >= boxX && x < boxX + boxSize && y >= boxY && y < boxY + boxSize;
  }
};

// The scene's truth as a window frame: noisy = truth + noise (sigma 0.1),
// denoised = truth + a leftover error (sigma 0.015), each seeded.
WindowFrame frameOf(const Scene& s, unsigned noiseSeed, unsigned leftoverSeed) {
  WindowFrame f;
  f.noisy = f.denoised = Image(s.width, s.height, 3);
  f.guides = motion::Guides{Image(s.width, s.height, 3), Image(s.width, s.height, 3),
                            Image(s.width, s.height, 1)};
  std::mt19937 noise(noiseSeed), leftover(leftoverSeed);
  std::normal_distribution<float> big(0.0f, 0.1f), small(0.0f, 0.015f);
  for (int y = 0; y < s.height; ++y)
    for (int x = 0; x < s.width; ++x) {
      const bool box = s.inBox(x, y);
      const float t = box ? 0.9f : texture(x + s.shift, y);
      for (int c = 0; c < 3; ++c) {
        f.noisy.floats().at(x, y, c) = t * (1.0f + 0.1f * c) + big(noise);
        f.denoised.floats().at(x, y, c) = t * (1.0f + 0.1f * c) + small(leftover);
        f.guides.albedo.floats().at(x, y, c) = box ? 0.9f : 0.5f;
      }
      f.guides.normal.floats().at(x, y, box ? 2 : 1) = 1.0f;
      f.guides.depth.floats().at(x, y, 0) = box ? 2.0f : 10.0f;
    }
  return f;
}

// Motion of a frame of `s` whose background moves `pan` px a frame to the
// left on screen and whose box moves `boxStep` px a frame to the right.
motion::MotionField motionOf(const Scene& s, float pan, float boxStep) {
  motion::MotionField m{Image(s.width, s.height, 2), Image(s.width, s.height, 2), "synthetic",
                        false};
  for (int y = 0; y < s.height; ++y)
    for (int x = 0; x < s.width; ++x) {
      const float step = s.inBox(x, y) ? boxStep : -pan;
      m.toPrevious.at(x, y, 0) = -step;
      m.toNext.at(x, y, 0) = step;
    }
  return m;
}

// `count` frames: the background panning `pan` px a frame, a box moving
// `boxStep` px a frame (none where boxSize is 0).
std::vector<WindowFrame> shot(int count, float pan, int boxStep, int boxSize, unsigned seed) {
  std::vector<WindowFrame> frames;
  for (int t = 0; t < count; ++t) {
    Scene s;
    s.shift = pan * t;
    s.boxX = 6 + boxStep * t, s.boxSize = boxSize;
    frames.push_back(frameOf(s, seed + t, seed + 100 + t));
    frames.back().motion = motionOf(s, pan, float(boxStep));
  }
  return frames;
}

std::vector<const WindowFrame*> windowOf(const std::vector<WindowFrame>& frames) {
  std::vector<const WindowFrame*> out;
  for (const WindowFrame& f : frames) out.push_back(&f);
  return out;
}

struct Agreement {
  double maxDifference = 0.0;
  double psnr = 0.0;  // dB, over the reference's peak
};

Agreement agreementOf(const Image& tensorPath, const Image& reference) {
  REQUIRE(tensorPath.sameShape(reference));
  double squares = 0.0, peak = 1e-12;
  Agreement a;
  for (std::size_t i = 0; i < reference.pixels.size(); ++i) {
    const double d = double(tensorPath.pixels[i]) - reference.pixels[i];
    a.maxDifference = std::max(a.maxDifference, std::abs(d));
    squares += d * d;
    peak = std::max(peak, std::abs(double(reference.pixels[i])));
  }
  const double mse = squares / std::max<std::size_t>(1, reference.pixels.size());
  a.psnr = mse > 0.0 ? 10.0 * std::log10(peak * peak / mse) : 999.0;
  return a;
}

void checkAgrees(const char* what, const Image& tensorPath, const Image& reference) {
  const Agreement a = agreementOf(tensorPath, reference);
  std::printf("agreement, %s: max |difference| %.2e, PSNR %.1f dB\n", what, a.maxDifference,
              a.psnr);
  CHECK(a.maxDifference < kMaxDifference);
  CHECK(a.psnr > kMinPsnr);
}

double maxDifference(const std::vector<double>& a, const std::vector<double>& b) {
  REQUIRE(a.size() == b.size());
  double out = 0.0;
  for (std::size_t i = 0; i < a.size(); ++i) out = std::max(out, std::abs(a[i] - b[i]));
  return out;
}

// The window on the device, filtered, and filterFrame's result on the same.
struct Both {
  std::vector<DeviceFrame> frames;
  DeviceTemporalResult device;
  TemporalResult onHost;  // device, copied back
  TemporalResult cpu;
};

Both filterBoth(const std::vector<const WindowFrame*>& window, std::size_t centre,
                const TemporalOptions& options = {}, const torch::Device& device = kCpu) {
  Both out;
  out.frames.reserve(window.size());
  std::vector<const DeviceFrame*> onDevice;
  for (const WindowFrame* f : window) {
    if (f) out.frames.push_back(toDevice(*f, device));
    onDevice.push_back(f ? &out.frames.back() : nullptr);
  }
  out.device = filterFrame(onDevice, centre, options);
  out.onHost = toHost(out.device, true);
  out.cpu = filterFrame(window, centre, options);
  return out;
}

// The decisions alike, the images and weights within the tolerance.
void checkSameFilter(const char* what, const Both& b) {
  const TemporalStats &d = b.onHost.stats, &c = b.cpu.stats;
  CHECK(d.neighbours == c.neighbours);
  CHECK(d.repeatedNoise == c.repeatedNoise);
  CHECK(d.relit == c.relit);
  CHECK(d.drifted == c.drifted);
  CHECK(d.changedLight == c.changedLight);
  REQUIRE(d.trusted.size() == c.trusted.size());
  for (std::size_t k = 0; k < c.trusted.size(); ++k)
    CHECK(d.trusted[k] == doctest::Approx(c.trusted[k]).epsilon(0.002));
  CHECK(d.historyShare == doctest::Approx(c.historyShare).epsilon(1e-4));
  REQUIRE(b.onHost.weights.neighbours.size() == b.cpu.weights.neighbours.size());
  for (std::size_t k = 0; k < b.cpu.weights.neighbours.size(); ++k) {
    const NeighbourWeights &dk = b.onHost.weights.neighbours[k], &ck = b.cpu.weights.neighbours[k];
    CHECK(dk.frame == ck.frame);
    CHECK(dk.relit == ck.relit);
    // Where the drift rule scaled it: a pixel at the threshold may differ by
    // rounding (on CUDA), as the trusted shares may.
    REQUIRE(dk.drifted.size() == ck.drifted.size());
    std::size_t differ = 0;
    for (std::size_t i = 0; i < ck.drifted.size(); ++i) differ += dk.drifted[i] != ck.drifted[i];
    CHECK(differ <= ck.drifted.size() / 500);
    CHECK(dk.resampling.taps == ck.resampling.taps);
    CHECK(maxDifference(dk.weight, ck.weight) < 1e-3);
  }
  checkAgrees(what, b.onHost.color, b.cpu.color);
  if (!b.cpu.history.empty()) {
    checkAgrees((std::string(what) + ", accumulated render").c_str(), b.onHost.history,
                b.cpu.history);
    checkAgrees((std::string(what) + ", its frames").c_str(), b.onHost.historyFrames,
                b.cpu.historyFrames);
    CHECK(b.onHost.stats.accumulatedFrames ==
          doctest::Approx(b.cpu.stats.accumulatedFrames).epsilon(1e-4));
  }
  CHECK(b.onHost.pastHistories.images.size() == b.cpu.pastHistories.images.size());
}

// A learned trust with every parameter drawn at random: 12-16-8-1.
LearnedTrust randomTrust(unsigned seed) {
  std::mt19937 random(seed);
  std::normal_distribution<float> weight(0.0f, 0.4f);
  std::vector<float> params(16 * 13 + 8 * 17 + 9);
  for (float& p : params) p = weight(random);
  return LearnedTrust({kTrustFeatureCount, 16, 8, 1}, params);
}

LearnedTrust constantTrust(float bias) {
  std::vector<float> params(kTrustFeatureCount, 0.0f);
  params.push_back(bias);
  return LearnedTrust({kTrustFeatureCount, 1}, params);
}

}  // namespace

TEST_CASE("device filter: a still window agrees with filterFrame") {
  const std::vector<WindowFrame> frames = shot(5, 0.0f, 0, 0, 100);
  const Both b = filterBoth(windowOf(frames), 2);
  CHECK(b.cpu.stats.historyShare > 0.6);  // the neighbours are used
  checkSameFilter("still", b);
}

TEST_CASE("device filter: a pan with a moving occluder agrees, disocclusions left out alike") {
  // Sub-pixel pan (Catmull-Rom and its bilinear fallback) and a box moving
  // 3 px a frame over it.
  const std::vector<WindowFrame> frames = shot(5, 0.5f, 3, 8, 300);
  const Both b = filterBoth(windowOf(frames), 2);
  std::size_t cubic = 0, dropped = 0;
  for (const NeighbourWeights& nb : b.cpu.weights.neighbours)
    for (unsigned char t : nb.resampling.taps) cubic += (t & 16) != 0, dropped += t == 0;
  CHECK(cubic > 0);    // Catmull-Rom taken ...
  CHECK(dropped > 0);  // ... and the uncovered background left out
  checkSameFilter("pan and occluder", b);
  // One-sided at the end of the shot, and a missing frame ends the chain.
  std::vector<const WindowFrame*> edge = {&frames[0], &frames[1], nullptr, &frames[3]};
  checkSameFilter("end of the shot", filterBoth(edge, 0));
  CHECK(filterBoth(edge, 3).onHost.stats.neighbours == 0);
}

TEST_CASE("device filter: relit neighbours and a change of light agree") {
  std::vector<WindowFrame> frames = shot(3, 0.0f, 0, 0, 500);
  for (unsigned t : {0u, 2u}) {
    for (float& v : frames[t].denoised.floats().pixels) v *= 1.2f;
    for (float& v : frames[t].noisy.floats().pixels) v *= 1.2f;
  }
  const Both relit = filterBoth(windowOf(frames), 1);
  CHECK(relit.cpu.stats.relit == 2);
  checkSameFilter("relit", relit);
  // Relit for the renders' light test over the frame alone, not the spread.
  TemporalOptions byLightTest;
  byLightTest.changedLightSpread = 1e9;
  const Both relitByLightTest = filterBoth(windowOf(frames), 1, byLightTest);
  CHECK(relitByLightTest.cpu.stats.relit == 2);
  checkSameFilter("relit by the light test", relitByLightTest);
  // A pass whose light moved (a torch's pool): the relit neighbours' pass is
  // not taken where its light came or went, alike.
  std::vector<Image> pool;
  std::vector<torch::Tensor> poolOnDevice;
  for (unsigned t = 0; t < frames.size(); ++t) {
    pool.push_back(frames[t].denoised.floats());
    const int from = t == 1 ? 0 : 4, to = t == 1 ? 8 : pool[t].width;  // where it is lit
    for (int y = 0; y < pool[t].height; ++y)
      for (int x = 0; x < pool[t].width; ++x)
        for (int c = 0; c < 3; ++c)
          if (x < from || x >= to) pool[t].at(x, y, c) *= 0.01f;
    poolOnDevice.push_back(pixelsToDevice(pool[t], kCpu));
  }
  const Image poolOnHost = filterWith(relit.cpu.weights, {&pool[0], &pool[1], &pool[2]});
  checkAgrees("a moved pool",
              pixelsToImage(filterWith(relit.device.weights,
                                       {&poolOnDevice[0], &poolOnDevice[1], &poolOnDevice[2]}),
                            pool[1].width, pool[1].height),
              poolOnHost);
  CHECK(poolOnHost.at(1, 4, 0) == pool[1].at(1, 4, 0));
  CHECK(poolOnHost.at(5, 4, 0) != pool[1].at(5, 4, 0));

  // Light changing from pixel to pixel: left out whole, the frame's own exactly.
  std::mt19937 random(42);
  std::uniform_real_distribution<float> factor(0.4f, 2.5f);
  for (unsigned t : {0u, 2u})
    for (std::size_t i = 0; i < frames[t].denoised.pixelCount(); ++i) {
      const float f = factor(random);
      for (int c = 0; c < 3; ++c) {
        frames[t].denoised.floats().pixels[3 * i + c] *= f;
        frames[t].noisy.floats().pixels[3 * i + c] *= f;
      }
    }
  const Both changed = filterBoth(windowOf(frames), 1);
  CHECK(changed.onHost.stats.changedLight == 2);
  CHECK(changed.onHost.color.pixels == frames[1].denoised.floats().pixels);
  CHECK(changed.onHost.history.pixels == frames[1].noisy.floats().pixels);
}

TEST_CASE("device filter: a light drifting over part of the frame is brought in alike") {
  std::vector<WindowFrame> frames = shot(5, 0.0f, 0, 0, 2000);
  for (int t = 0; t < 5; ++t) {  // the top half 4 % dimmer a frame before the last
    WindowFrame& f = frames[std::size_t(t)];
    for (Image* image : {&f.denoised.floats(), &f.noisy.floats()})
      for (int y = 0; y < image->height / 2; ++y)
        for (int x = 0; x < image->width; ++x)
          for (int c = 0; c < 3; ++c) image->at(x, y, c) *= 1.0f + 0.04f * float(t - 4);
  }
  TemporalOptions options;
  options.driftBox = 3;
  const Both drifted = filterBoth(windowOf(frames), 4, options);
  CHECK(drifted.cpu.stats.drifted >= 2);
  checkSameFilter("drifted", drifted);
  std::vector<torch::Tensor> onDevice;
  std::vector<const Image*> results;
  for (const WindowFrame& f : frames) {
    onDevice.push_back(pixelsToDevice(f.denoised.floats(), kCpu));
    results.push_back(&f.denoised.floats());
  }
  std::vector<const torch::Tensor*> onDeviceOf;
  for (const torch::Tensor& t : onDevice) onDeviceOf.push_back(&t);
  checkAgrees("drifted, filterWith",
              pixelsToImage(filterWith(drifted.device.weights, onDeviceOf),
                            frames[4].denoised.width(), frames[4].denoised.height()),
              filterWith(drifted.cpu.weights, results));
}

TEST_CASE("device filter: a neighbour repeating the frame's noise is left out, as on the CPU") {
  const std::vector<WindowFrame> one = shot(1, 0.0f, 0, 0, 700);
  const std::vector<WindowFrame> repeated(5, one[0]);
  const Both b = filterBoth(windowOf(repeated), 2);
  CHECK(b.onHost.stats.repeatedNoise == 4);
  CHECK(b.cpu.stats.repeatedNoise == 4);
  CHECK(b.onHost.color.pixels == repeated[2].denoised.floats().pixels);
  CHECK(b.onHost.stats.accumulatedFrames == 1.0);
}

TEST_CASE(
    "device filter: the learned trust weighs as on the CPU; trusting nothing gives the frame") {
  const std::vector<WindowFrame> frames = shot(5, 0.5f, 3, 8, 900);
  TemporalOptions options;
  options.learnedTrust = std::make_shared<LearnedTrust>(randomTrust(11));
  std::vector<TrustSamples> seen;
  options.observeTrust = [&](const TrustSamples& s) { seen.push_back(s); };
  const Both b = filterBoth(windowOf(frames), 2, options);
  checkSameFilter("learned trust", b);
  // Its view: the device's observation first, then the CPU's.
  REQUIRE(seen.size() == 2);
  REQUIRE(seen[0].features.size() == seen[1].features.size());
  CHECK(seen[0].frames == seen[1].frames);
  double features = 0.0;
  for (std::size_t k = 0; k < seen[0].features.size(); ++k)
    for (std::size_t i = 0; i < seen[0].features[k].size(); ++i)
      features =
          std::max(features, double(std::abs(seen[0].features[k][i] - seen[1].features[k][i])));
  std::printf("agreement, learned trust's features: max |difference| %.2e\n", features);
  CHECK(features < 1e-3);

  options.observeTrust = nullptr;
  options.learnedTrust = std::make_shared<LearnedTrust>(constantTrust(-100.0f));
  const Both none = filterBoth(windowOf(frames), 2, options);
  CHECK(none.onHost.color.pixels == frames[2].denoised.floats().pixels);
  CHECK(none.cpu.color.pixels == frames[2].denoised.floats().pixels);
}

TEST_CASE("device filter: past histories, their mean and the blend agree") {
  std::vector<WindowFrame> frames = shot(5, 0.0f, 0, 0, 1100);
  for (unsigned t = 0; t < frames.size(); ++t)
    frames[t].history = shot(1, 0.0f, 0, 0, 1200 + t)[0].denoised;
  // A light that moved since over the left half of the past histories.
  for (unsigned t : {0u, 1u})
    for (int y = 0; y < frames[t].history.height(); ++y)
      for (int x = 0; x < 12; ++x)
        for (int c = 0; c < 3; ++c) frames[t].history.floats().at(x, y, c) += 0.6f;
  const Both b = filterBoth(windowOf(frames), 2);
  REQUIRE(b.cpu.pastHistories.images.size() == 2);
  checkSameFilter("with histories", b);
  const Image& own = frames[2].history.floats();
  const torch::Tensor ownOnDevice = pixelsToDevice(own, kCpu);
  const torch::Tensor mean = historyMean(ownOnDevice, b.device);
  const Image cpuMean = historyMean(own, b.cpu);
  checkAgrees("history mean", pixelsToImage(mean, own.width, own.height), cpuMean);
  const torch::Tensor blended = blendWithHistory(b.device.color, mean, 0.35);
  checkAgrees("blend", pixelsToImage(blended, own.width, own.height),
              blendWithHistory(b.cpu.color, cpuMean, 0.35));
  CHECK_THROWS_AS(blendWithHistory(b.device.color, mean.slice(1, 0, 4), 0.35),
                  std::invalid_argument);

  // The mean's weights for another image's histories (a light pass's), on the
  // host from either path; with them filterWith gives the colour's mean.
  const FilterWeights onCpu = historyWeights(own, b.cpu, b.cpu.weights);
  const FilterWeights fromDevice = historyWeights(ownOnDevice, b.device, b.cpu.weights);
  REQUIRE(onCpu.neighbours.size() == 2);
  REQUIRE(fromDevice.neighbours.size() == 2);
  for (std::size_t k = 0; k < 2; ++k) {
    CHECK(onCpu.neighbours[k].frame == b.cpu.pastHistories.frames[k]);
    CHECK(fromDevice.neighbours[k].frame == onCpu.neighbours[k].frame);
    CHECK(maxDifference(fromDevice.neighbours[k].weight, onCpu.neighbours[k].weight) < 1e-5);
  }
  const std::vector<const Image*> histories = {&frames[0].history.floats(),
                                               &frames[1].history.floats(), &own};
  checkAgrees("history mean by its weights", filterWith(onCpu, histories), cpuMean);

  // A pan: every history was resampled on its way in and none counts.
  std::vector<WindowFrame> pan = shot(3, 1.0f, 0, 0, 1300);
  for (WindowFrame& f : pan) f.history = f.denoised;
  const Both panned = filterBoth(windowOf(pan), 1);
  CHECK(panned.device.pastHistories.empty());
  CHECK(historyMean(ownOnDevice, panned.device).equal(ownOnDevice));
}

TEST_CASE("device filter: its weights filter another image as on the CPU") {
  const std::vector<WindowFrame> frames = shot(5, 0.5f, 3, 8, 1500);
  const Both b = filterBoth(windowOf(frames), 2);
  std::vector<torch::Tensor> results, passes;
  std::vector<Image> hostPasses;
  for (std::size_t t = 0; t < frames.size(); ++t) {
    results.push_back(b.frames[t].denoised);
    Image pass = shot(1, 0.5f * t, 0, 0, 1600 + t)[0].denoised.floats();  // a light pass of its own
    for (float& v : pass.pixels) v *= 0.5f;
    passes.push_back(pixelsToDevice(pass, kCpu));
    hostPasses.push_back(std::move(pass));
  }
  auto pointers = [](const std::vector<torch::Tensor>& images) {
    std::vector<const torch::Tensor*> out;
    for (const torch::Tensor& t : images) out.push_back(&t);
    return out;
  };
  // With the results it gives the filtered colour bit for bit.
  CHECK(filterWith(b.device.weights, pointers(results)).equal(b.device.color));
  std::vector<const Image*> hostImages;
  for (const Image& p : hostPasses) hostImages.push_back(&p);
  const Image& shape = hostPasses[0];
  checkAgrees(
      "a pass by the weights",
      pixelsToImage(filterWith(b.device.weights, pointers(passes)), shape.width, shape.height),
      filterWith(b.cpu.weights, hostImages));
  // The weights copied to the host filter it there too.
  checkAgrees("a pass by the weights on the host", filterWith(b.onHost.weights, hostImages),
              filterWith(b.cpu.weights, hostImages));
  std::vector<const torch::Tensor*> noCentre = pointers(results);
  noCentre[2] = nullptr;
  CHECK_THROWS_AS(filterWith(b.device.weights, noCentre), std::invalid_argument);
}

TEST_CASE("device filter: light that moves with the view counts where the surface stood still") {
  // A pan with an occluder, its view-dependent share rising across the frame.
  std::vector<WindowFrame> frames = shot(5, 0.5f, 3, 8, 1800);
  for (WindowFrame& f : frames) {
    f.viewDependent = Image(f.denoised.width(), f.denoised.height(), 1);
    for (int y = 0; y < f.viewDependent.height(); ++y)
      for (int x = 0; x < f.viewDependent.width(); ++x)
        f.viewDependent.floats().at(x, y, 0) = float(x) / f.viewDependent.width();
  }
  // Partly still: the pan moves 0.5 px a frame, the share falls to nothing at 2.
  TemporalOptions options;
  options.viewDependentMotion = 2.0;
  const Both b = filterBoth(windowOf(frames), 2, options);
  checkSameFilter("view-dependent share", b);
  const Both without = filterBoth(windowOf(shot(5, 0.5f, 3, 8, 1800)), 2, options);
  CHECK(b.cpu.stats.historyShare < without.cpu.stats.historyShare);  // the share took weight
  // A glossy pass filtered over time counts its neighbours where the surface stood still only.
  std::vector<torch::Tensor> results;
  std::vector<const Image*> hostResults;
  for (std::size_t t = 0; t < frames.size(); ++t) {
    results.push_back(b.frames[t].denoised);
    hostResults.push_back(&frames[t].denoised.floats());
  }
  std::vector<const torch::Tensor*> pointers;
  for (const torch::Tensor& r : results) pointers.push_back(&r);
  const Image& own = frames[2].denoised.floats();
  const Image pass = filterWith(b.cpu.weights, hostResults, 2.0);
  CHECK(pass.pixels != own.pixels);
  checkAgrees("a view-dependent pass by the weights",
              pixelsToImage(filterWith(b.device.weights, pointers, 2.0), own.width, own.height),
              pass);
  frames[2].viewDependent = Image(4, 4, 1);
  CHECK_THROWS_AS(filterBoth(windowOf(frames), 2, options), std::invalid_argument);
}

TEST_CASE("device filter: motion of another size throws as on the CPU") {
  std::vector<WindowFrame> frames = shot(3, 0.0f, 0, 0, 1700);
  frames[2].motion = motionOf(Scene{16, 12}, 0.0f, 0.0f);
  const DeviceFrame a = toDevice(frames[0], kCpu), b = toDevice(frames[1], kCpu),
                    c = toDevice(frames[2], kCpu);
  CHECK_THROWS_AS(filterFrame({&a, &b, &c}, 1), std::invalid_argument);
  CHECK_THROWS_AS(filterFrame({&a, nullptr, &c}, 1), std::invalid_argument);
}

// The same windows on a GPU, where this LibTorch and machine have one
// (bench/gpu/check_cuda.sh runs this test there).
TEST_CASE("device filter: on CUDA as on the CPU" * doctest::skip(!torch::cuda::is_available())) {
  const torch::Device cuda(torch::kCUDA);
  const std::vector<WindowFrame> still = shot(5, 0.0f, 0, 0, 100);
  checkSameFilter("still, CUDA", filterBoth(windowOf(still), 2, {}, cuda));
  const std::vector<WindowFrame> pan = shot(5, 0.5f, 3, 8, 300);
  checkSameFilter("pan and occluder, CUDA", filterBoth(windowOf(pan), 2, {}, cuda));
  TemporalOptions learned;
  learned.learnedTrust = std::make_shared<LearnedTrust>(randomTrust(11));
  checkSameFilter("learned trust, CUDA", filterBoth(windowOf(pan), 2, learned, cuda));
  std::vector<WindowFrame> relit = shot(3, 0.0f, 0, 0, 500);
  for (unsigned t : {0u, 2u}) {
    for (float& v : relit[t].denoised.floats().pixels) v *= 1.2f;
    for (float& v : relit[t].noisy.floats().pixels) v *= 1.2f;
  }
  checkSameFilter("relit, CUDA", filterBoth(windowOf(relit), 1, {}, cuda));
}

#ifdef DN_TEST_READS_EXR
TEST_CASE("device filter: the Cycles renders of testdata/sequence agree with filterFrame") {
  // A box sweeping in front of a room; each render, box-filtered 3 x 3,
  // stands in for its denoised result (the filter needs only that it be smoother).
  std::vector<WindowFrame> frames;
  for (int n = 1; n <= 6; ++n) {
    const std::string path =
        std::string(DN_TESTDATA) + "/sequence/spp4.000" + std::to_string(n) + ".exr";
    const FrameBuffers buffers = readFrame(path);
    WindowFrame f;
    f.noisy = buffers.get("color");
    f.denoised = f.noisy;
    const int w = f.noisy.width(), h = f.noisy.height();
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        for (int c = 0; c < 3; ++c) {
          float sum = 0.0f;
          int count = 0;
          for (int v = std::max(0, y - 1); v <= std::min(h - 1, y + 1); ++v)
            for (int u = std::max(0, x - 1); u <= std::min(w - 1, x + 1); ++u, ++count)
              sum += f.noisy.floats().at(u, v, c);
          f.denoised.floats().at(x, y, c) = sum / count;
        }
    auto guide = [&](const char* name) { return buffers.has(name) ? buffers.get(name) : Image(); };
    f.guides = motion::Guides{guide("albedo"), guide("normal"), guide("depth")};
    auto field = motion::readMotion(path, w, h);
    REQUIRE(field);
    f.motion = std::move(*field);
    frames.push_back(std::move(f));
  }
  // Every frame as the centre: its half-float guides tie with the tests'
  // thresholds where float and double differ (a distance-2 neighbour of frame 4).
  TemporalOptions options;
  options.radius = 2;
  for (std::size_t centre = 0; centre < frames.size(); ++centre) {
    const std::string what = "testdata/sequence, frame " + std::to_string(centre + 1);
    checkSameFilter(what.c_str(), filterBoth(windowOf(frames), centre, options));
  }
}
#endif
