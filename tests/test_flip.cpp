#include <doctest/doctest.h>

#include <cmath>
#include <cstdint>
#include <stdexcept>

#include "dn/flip.h"

using dn::Image;
namespace flip = dn::flip;

namespace {

constexpr int kWidth = 40;
constexpr int kHeight = 30;

// Integer hash noise in [0,1); the Python script that produced the reference
// numbers below computes the same images bit for bit.
double hashNoise(std::uint32_t i, std::uint32_t salt) {
  std::uint32_t h = i * 2654435761u + salt * 40503u;
  h ^= h >> 15;
  h *= 2246822519u;
  h ^= h >> 13;
  return (h & 0xffffu) / 65536.0;
}

// sRGB pair: gradients over a checkerboard, and the same with noise.
void ldrPair(Image& reference, Image& test) {
  reference = Image(kWidth, kHeight, 3);
  test = Image(kWidth, kHeight, 3);
  for (int y = 0; y < kHeight; ++y)
    for (int x = 0; x < kWidth; ++x) {
      const std::uint32_t i = static_cast<std::uint32_t>(y * kWidth + x);
      const double base[3] = {x / double(kWidth - 1), y / double(kHeight - 1),
                              (x / 8 + y / 8) % 2 ? 0.25 : 0.75};
      for (int c = 0; c < 3; ++c) {
        reference.at(x, y, c) = static_cast<float>(base[c]);
        const double noisy = base[c] + 0.2 * (hashNoise(i, c + 1) - 0.5);
        test.at(x, y, c) = static_cast<float>(std::min(std::max(noisy, 0.0), 1.0));
      }
    }
}

// Linear HDR pair: a luminance ramp up to ~8, two tints, multiplicative noise.
void hdrPair(Image& reference, Image& test) {
  reference = Image(kWidth, kHeight, 3);
  test = Image(kWidth, kHeight, 3);
  for (int y = 0; y < kHeight; ++y)
    for (int x = 0; x < kWidth; ++x) {
      const std::uint32_t i = static_cast<std::uint32_t>(y * kWidth + x);
      const double luminance = 0.05 + 8.0 * std::pow(x / double(kWidth - 1), 3.0);
      const double tint[2][3] = {{1.0, 0.8, 0.6}, {0.5, 0.7, 1.0}};
      for (int c = 0; c < 3; ++c) {
        const float v = static_cast<float>(luminance * tint[y < kHeight / 2 ? 0 : 1][c]);
        reference.at(x, y, c) = v;
        test.at(x, y, c) = v * static_cast<float>(0.5 + hashNoise(i, c + 7));
      }
    }
}

double mean(const Image& map) { return flip::statistics(map).mean; }

Image smoothImage(int width, int height, double shift) {
  Image image(width, height, 3);
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) {
      const double u = (x + shift) / width, v = double(y) / height;
      image.at(x, y, 0) = static_cast<float>(0.5 + 0.4 * std::sin(6.0 * u + 2.0 * v));
      image.at(x, y, 1) = static_cast<float>(0.5 + 0.4 * std::cos(5.0 * v - 3.0 * u));
      image.at(x, y, 2) = static_cast<float>(0.4 + 0.3 * u * v);
    }
  return image;
}

}  // namespace

// Expected values: flip_evaluator 1.7 (pip package flip-evaluator), float32
// numpy copies of the same images, e.g.
//   e, _, params = flip_evaluator.evaluate(ref, test, "LDR", applyMagma=False)
//   e.astype(np.float64).mean(), e[y, x], params
TEST_CASE("LDR-FLIP agrees with flip-evaluator on a small pair") {
  Image reference, test;
  ldrPair(reference, test);
  const Image error = flip::ldrErrorMap(reference, test);
  REQUIRE(error.channels == 1);
  REQUIRE(error.width == kWidth);
  REQUIRE(error.height == kHeight);
  CHECK(mean(error) == doctest::Approx(0.1327010).epsilon(1e-4));
  CHECK(error.at(0, 0, 0) == doctest::Approx(0.101914).epsilon(1e-3));
  CHECK(error.at(20, 15, 0) == doctest::Approx(0.101984).epsilon(1e-3));
  CHECK(error.at(39, 29, 0) == doctest::Approx(0.263157).epsilon(1e-3));
  CHECK(mean(flip::ldrErrorMap(reference, test, 30.0)) == doctest::Approx(0.2279951).epsilon(1e-4));
}

TEST_CASE("HDR-FLIP agrees with flip-evaluator on a small pair") {
  Image reference, test;
  hdrPair(reference, test);
  const flip::ExposureRange range = flip::exposureRange(reference);
  CHECK(range.start == doctest::Approx(-1.6535336).epsilon(1e-5));
  CHECK(range.stop == doctest::Approx(1.3919331).epsilon(1e-5));
  CHECK(range.count == 4);

  const Image error = flip::hdrErrorMap(reference, test);
  CHECK(mean(error) == doctest::Approx(0.1499299).epsilon(1e-4));
  CHECK(error.at(0, 0, 0) == doctest::Approx(0.206277).epsilon(1e-3));
  CHECK(error.at(20, 15, 0) == doctest::Approx(0.217624).epsilon(1e-3));
  CHECK(error.at(39, 29, 0) == doctest::Approx(0.120038).epsilon(1e-3));

  flip::HdrOptions hable;
  hable.tonemapper = flip::Tonemapper::Hable;
  CHECK(flip::exposureRange(reference, hable).start == doctest::Approx(-1.0917056).epsilon(1e-5));
  CHECK(mean(flip::hdrErrorMap(reference, test, hable)) ==
        doctest::Approx(0.1367054).epsilon(1e-4));

  flip::HdrOptions reinhard;
  reinhard.tonemapper = flip::Tonemapper::Reinhard;
  CHECK(flip::exposureRange(reference, reinhard).stop == doctest::Approx(2.8111365).epsilon(1e-5));
  CHECK(mean(flip::hdrErrorMap(reference, test, reinhard)) ==
        doctest::Approx(0.2092569).epsilon(1e-4));

  flip::HdrOptions fixed;
  fixed.startExposure = -2.0;
  fixed.stopExposure = 1.0;
  fixed.numExposures = 4;
  CHECK(mean(flip::hdrErrorMap(reference, test, fixed)) ==
        doctest::Approx(0.1494805).epsilon(1e-4));
}

TEST_CASE("identical images have zero error") {
  Image reference, test;
  ldrPair(reference, test);
  for (float v : flip::ldrErrorMap(test, test).pixels) REQUIRE(v == 0.0f);
  hdrPair(reference, test);
  for (float v : flip::hdrErrorMap(test, test).pixels) REQUIRE(v == 0.0f);
}

TEST_CASE("error maps lie in [0,1] and LDR-FLIP is symmetric") {
  Image reference, test;
  ldrPair(reference, test);
  const Image forward = flip::ldrErrorMap(reference, test);
  const Image backward = flip::ldrErrorMap(test, reference);
  for (std::size_t i = 0; i < forward.pixels.size(); ++i) {
    REQUIRE(forward.pixels[i] >= 0.0f);
    REQUIRE(forward.pixels[i] <= 1.0f);
    REQUIRE(forward.pixels[i] == doctest::Approx(backward.pixels[i]).epsilon(1e-5));
  }
  hdrPair(reference, test);
  for (float v : flip::hdrErrorMap(reference, test).pixels) {
    REQUIRE(v >= 0.0f);
    REQUIRE(v <= 1.0f);
  }
  // Huge but finite radiance saturates instead of overflowing the tonemapper.
  for (int c = 0; c < 3; ++c) test.at(7, 7, c) = 3e38f;
  for (float v : flip::hdrErrorMap(reference, test).pixels) {
    REQUIRE(v >= 0.0f);
    REQUIRE(v <= 1.0f);
  }
}

TEST_CASE("black against white is a large error, a small shift a small one") {
  // flip-evaluator gives 0.9673883 for every pixel of black vs white.
  const Image black(16, 16, 3, 0.0f), white(16, 16, 3, 1.0f);
  const flip::Stats stats = flip::statistics(flip::ldrErrorMap(black, white));
  CHECK(stats.min == doctest::Approx(0.9673883).epsilon(1e-4));
  CHECK(stats.max == doctest::Approx(0.9673883).epsilon(1e-4));

  const Image original = smoothImage(64, 48, 0.0);
  const double subpixel = mean(flip::ldrErrorMap(original, smoothImage(64, 48, 0.5)));
  const double larger = mean(flip::ldrErrorMap(original, smoothImage(64, 48, 4.0)));
  // flip-evaluator: 0.0785344 and 0.3478710.
  CHECK(subpixel == doctest::Approx(0.0785344).epsilon(1e-4));
  CHECK(larger == doctest::Approx(0.3478710).epsilon(1e-4));
  CHECK(subpixel < 0.1 * stats.mean);
  CHECK(larger > 4.0 * subpixel);
}

TEST_CASE("extra channels are ignored and out-of-range sRGB values are clamped") {
  Image reference, test;
  ldrPair(reference, test);
  Image withAlpha(kWidth, kHeight, 4, 0.3f);
  Image overRange = test;
  for (int y = 0; y < kHeight; ++y)
    for (int x = 0; x < kWidth; ++x) {
      for (int c = 0; c < 3; ++c) withAlpha.at(x, y, c) = test.at(x, y, c);
      if (test.at(x, y, 0) >= 1.0f) overRange.at(x, y, 0) = 3.0f;
      if (test.at(x, y, 1) <= 0.0f) overRange.at(x, y, 1) = -1.0f;
    }
  const Image expected = flip::ldrErrorMap(reference, test);
  CHECK(flip::ldrErrorMap(reference, withAlpha).pixels == expected.pixels);
  CHECK(flip::ldrErrorMap(reference, overRange).pixels == expected.pixels);
}

TEST_CASE("statistics of a known error map") {
  Image map(5, 2, 1);
  const float values[10] = {0.0f, 0.1f, 0.2f, 0.3f, 0.4f, 0.5f, 0.6f, 0.7f, 0.8f, 0.9f};
  for (int i = 0; i < 10; ++i) map.pixels[i] = values[9 - i];
  const flip::Stats s = flip::statistics(map);
  CHECK(s.mean == doctest::Approx(0.45));
  CHECK(s.min == doctest::Approx(0.0));
  CHECK(s.max == doctest::Approx(0.9));
  CHECK(s.p50 == doctest::Approx(0.45));
  CHECK(s.p25 == doctest::Approx(0.225));
  CHECK(s.p99 == doctest::Approx(0.891));
  // Running sums 0, .1, .3, .6, 1.0, 1.5, 2.1, 2.8, 3.6, 4.5: half of 4.5 is passed at 0.7.
  CHECK(s.weightedMedian == doctest::Approx(0.7));
  CHECK(s.weightedQuartile1 == doctest::Approx(0.5));
  CHECK(s.weightedQuartile3 == doctest::Approx(0.8));
}

TEST_CASE("magma heatmap uses the colormap's ends and nearest entries") {
  Image map(3, 1, 1);
  map.pixels = {0.0f, 1.0f, 0.5f};
  const Image heat = flip::magmaHeatmap(map);
  REQUIRE(heat.channels == 3);
  CHECK(heat.at(0, 0, 0) == doctest::Approx(0.001462));
  CHECK(heat.at(0, 0, 2) == doctest::Approx(0.013866));
  CHECK(heat.at(1, 0, 0) == doctest::Approx(0.987053));
  CHECK(heat.at(1, 0, 1) == doctest::Approx(0.991438));
  // 0.5 * 255 + 0.5 = 128: matplotlib's magma entry 128.
  CHECK(heat.at(2, 0, 0) == doctest::Approx(0.716387));
  CHECK(heat.at(2, 0, 1) == doctest::Approx(0.214982));
}

TEST_CASE("bad inputs are rejected") {
  Image reference, test;
  ldrPair(reference, test);
  CHECK_THROWS_AS(flip::ldrErrorMap(reference, Image(kWidth + 1, kHeight, 3)),
                  std::invalid_argument);
  CHECK_THROWS_AS(flip::ldrErrorMap(Image(kWidth, kHeight, 1), Image(kWidth, kHeight, 1)),
                  std::invalid_argument);
  CHECK_THROWS_AS(flip::ldrErrorMap(Image(), Image()), std::invalid_argument);
  CHECK_THROWS_AS(flip::ldrErrorMap(reference, test, 0.0), std::invalid_argument);
  flip::HdrOptions backwards;
  backwards.startExposure = 2.0;
  backwards.stopExposure = -1.0;
  CHECK_THROWS_AS(flip::hdrErrorMap(reference, test, backwards), std::invalid_argument);
  flip::HdrOptions none;
  none.numExposures = 0;
  CHECK_THROWS_AS(flip::hdrErrorMap(reference, test, none), std::invalid_argument);
  CHECK_THROWS_AS(flip::statistics(Image()), std::invalid_argument);
  Image infinite = test;
  infinite.at(3, 4, 1) = INFINITY;
  CHECK_THROWS_AS(flip::hdrErrorMap(reference, infinite), std::invalid_argument);
  CHECK_THROWS_AS(flip::exposureRange(infinite), std::invalid_argument);
  Image notANumber = test;
  notANumber.at(5, 6, 2) = NAN;
  CHECK_THROWS_AS(flip::hdrErrorMap(notANumber, test), std::invalid_argument);
}

TEST_CASE("exposure range of mostly and entirely black references") {
  // flip-evaluator 1.7 on a 2x2 grey image with luminances 0, 0, 0, 4: start
  // -0.91670, stop 24.08330, 25 exposures (the median is floored at float epsilon).
  Image mostlyBlack(2, 2, 3, 0.0f);
  for (int c = 0; c < 3; ++c) mostlyBlack.at(1, 1, c) = 4.0f;
  const flip::ExposureRange dark = flip::exposureRange(mostlyBlack);
  CHECK(dark.start == doctest::Approx(-0.91670).epsilon(1e-4));
  CHECK(dark.stop == doctest::Approx(24.08330).epsilon(1e-5));
  CHECK(dark.count == 25);

  const Image black(24, 24, 3, 0.0f);
  Image lit(24, 24, 3, 0.0f);
  lit.at(12, 12, 0) = 5.0f;
  const flip::ExposureRange range = flip::exposureRange(black);
  CHECK(range.start == 0.0);
  CHECK(range.stop == 0.0);
  const Image error = flip::hdrErrorMap(black, lit);
  CHECK(error.at(12, 12, 0) > 0.5f);
  CHECK(error.at(0, 0, 0) == 0.0f);
}
