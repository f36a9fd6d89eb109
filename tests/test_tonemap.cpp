#include <doctest/doctest.h>

#include <cmath>
#include <limits>
#include <stdexcept>

#include "dn/ocio_preview.h"
#include "dn/tonemap.h"

using namespace dn;
namespace tmo = dn::tonemap;

TEST_CASE("curves match their closed forms") {
  CHECK(tmo::gamma(1.0f) == doctest::Approx(0.47));
  CHECK(tmo::gamma(6.0f) == doctest::Approx(0.47 * std::pow(6.0, 1 / 2.4)));
  CHECK(tmo::log(6.0f) == doctest::Approx(0.51 * std::log(7.0)));
  CHECK(tmo::reinhard(1.0f) == doctest::Approx(0.5));
  CHECK(tmo::reinhard(3.0f) == doctest::Approx(0.75));
  CHECK(tmo::srgbEncode(0.0031308f) == doctest::Approx(0.0404500).epsilon(1e-4));
  CHECK(tmo::srgbEncode(1.0f) == doctest::Approx(1.0));
  CHECK(tmo::srgbEncode(0.214041f) == doctest::Approx(0.5).epsilon(1e-4));
}

TEST_CASE("every curve has an exact inverse on [0, 6]") {
  for (auto curve : {tmo::Curve::Linear, tmo::Curve::Gamma, tmo::Curve::Log, tmo::Curve::Reinhard,
                     tmo::Curve::Srgb}) {
    CAPTURE(tmo::curveName(curve));
    for (float v = 0.0f; v <= 6.0f; v += 0.0137f)
      CHECK(tmo::applyInverse(curve, tmo::apply(curve, v)) == doctest::Approx(v).epsilon(1e-5));
  }
}

TEST_CASE("curves are monotonic and map negatives and NaN to zero") {
  for (auto curve : {tmo::Curve::Gamma, tmo::Curve::Log, tmo::Curve::Reinhard, tmo::Curve::Srgb}) {
    CHECK(tmo::apply(curve, -1.0f) == 0.0f);
    CHECK(tmo::apply(curve, NAN) == 0.0f);
    float previous = -1.0f;
    for (float v = 0.0f; v < 100.0f; v += 0.25f) {
      float t = tmo::apply(curve, v);
      CHECK(t > previous);
      previous = t;
    }
  }
  CHECK(tmo::reinhard(INFINITY) == 1.0f);
}

TEST_CASE("clamp and image-wide application") {
  Image img(2, 1, 3);
  img.pixels = {-1.0f, 0.5f, 7.0f, NAN, 6.0f, 2.0f};
  tmo::clamp(img, 0.0f, tmo::kHdrMax);
  CHECK(img.pixels == std::vector<float>{0.0f, 0.5f, 6.0f, 0.0f, 6.0f, 2.0f});
  tmo::apply(tmo::Curve::Log, img);
  tmo::applyInverse(tmo::Curve::Log, img);
  CHECK(img.pixels[2] == doctest::Approx(6.0f));
  CHECK(tmo::curveFromName("log") == tmo::Curve::Log);
  CHECK_THROWS_AS(tmo::curveFromName("aces"), std::invalid_argument);
}

TEST_CASE("OpenColorIO preview maps scene-linear to display range") {
  Image img(3, 1, 4);
  img.pixels = {0, 0, 0, 1, 0.18f, 0.18f, 0.18f, 1, 4, 4, 4, 1};
  tmo::ocioPreview(img);
  CHECK(img.pixels[0] == doctest::Approx(0.0).epsilon(0.02));
  CHECK(img.pixels[4] > 0.2f);  // mid grey lands mid-range
  CHECK(img.pixels[4] < 0.7f);
  CHECK(img.pixels[8] > img.pixels[4]);
  CHECK(img.pixels[3] == 1.0f);  // alpha untouched
  CHECK_FALSE(tmo::ocioDescribeConfig().empty());
}

TEST_CASE("autoexposure scales the clamped mean luminance to the target") {
  // Three grey pixels of luminance 0.1 and a light far above the ceiling: the
  // light counts as 6, so 3 * 0.1 s + 6 = 4 * 2 gives s = 20 / 3.
  Image image(4, 1, 3, 0.1f);
  for (int c = 0; c < 3; ++c) image.at(3, 0, c) = 100.0f;
  CHECK(tmo::exposureForMean(image, 2.0) == doctest::Approx(20.0 / 3.0).epsilon(1e-6));
  // Rec. 709 weights: a pure green pixel of 1 has luminance 0.7152.
  Image green(1, 1, 3, 0.0f);
  green.at(0, 0, 1) = 1.0f;
  CHECK(tmo::exposureForMean(green, 0.3576) == doctest::Approx(0.5).epsilon(1e-6));
  // NaN, Inf and negatives are dark; a black frame keeps its exposure; limits hold.
  Image odd(3, 1, 3, 0.2f);
  odd.at(1, 0, 0) = std::nanf("");
  odd.at(2, 0, 1) = -5.0f;
  odd.at(2, 0, 0) = std::numeric_limits<float>::infinity();
  const double s = tmo::exposureForMean(odd, 0.1);
  CHECK(std::isfinite(s));
  CHECK(s * 0.2 / 3.0 == doctest::Approx(0.1).epsilon(1e-6));  // one valid pixel of three
  CHECK(tmo::exposureForMean(Image(2, 2, 3, 0.0f), 0.3) == 1.0);
  CHECK(tmo::exposureForMean(Image(2, 2, 3, 1e-6f), 0.3) == 64.0);
  CHECK(tmo::exposureForMean(Image(2, 2, 3, 5.0f), 0.3, 6.0, 4.0) == 0.25);
  CHECK_THROWS_AS(tmo::exposureForMean(Image(2, 2, 1, 1.0f), 0.3), std::invalid_argument);
}
