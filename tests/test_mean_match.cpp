// Local mean matching (dn/experiments/mean_match.h): the Gaussian blur against closed-form
// values, and the correction against a known reference.
#include <cmath>
#include <limits>

#include "doctest_torch.h"

#include "dn/experiments/highlights.h"
#include "dn/experiments/mean_match.h"

using namespace dn;

namespace {

// A smooth positive HDR image (1,3,h,w): a gradient with a different slope per channel.
torch::Tensor smoothReference(int64_t h, int64_t w) {
  auto y = torch::linspace(0.2, 1.5, h).view({1, 1, h, 1});
  auto x = torch::linspace(0.5, 1.0, w).view({1, 1, 1, w});
  return torch::cat({y * x, 0.5 * y + 0.2 * x, 0.3 + 0.0 * y * x}, 1);
}

// Zero-mean Monte Carlo-like noise at the highest frequency: +a, -a in a checkerboard.
torch::Tensor checkerboard(int64_t h, int64_t w, double amplitude) {
  auto parity = (torch::arange(h).view({h, 1}) + torch::arange(w).view({1, w})).remainder(2);
  return (amplitude * (2.0 * parity - 1.0)).to(torch::kFloat32).view({1, 1, h, w});
}

}  // namespace

TEST_CASE("gaussianBlur keeps constants and spreads an impulse like the continuous Gaussian") {
  auto constant = torch::full({1, 2, 9, 11}, 0.75f);
  CHECK(torch::allclose(gaussianBlur(constant, 2.0), constant, 1e-6, 1e-6));

  auto impulse = torch::zeros({1, 1, 41, 41});
  impulse[0][0][20][20] = 1.0f;
  const double sigma = 2.0;
  auto blurred = gaussianBlur(impulse, sigma);
  CHECK(blurred.sum().item<double>() == doctest::Approx(1.0).epsilon(1e-5));
  const double pi = std::acos(-1.0);
  CHECK(blurred[0][0][20][20].item<double>() ==
        doctest::Approx(1.0 / (2 * pi * sigma * sigma)).epsilon(0.01));
  CHECK(blurred[0][0][20][24].item<double>() ==
        doctest::Approx(std::exp(-0.5 * 4.0) / (2 * pi * sigma * sigma)).epsilon(0.01));
  CHECK(torch::equal(gaussianBlur(impulse, 0.0), impulse));
}

TEST_CASE("matchLocalMean removes a brightness and colour bias but keeps the noise-free detail") {
  const auto reference = smoothReference(32, 40);
  const auto render = reference + checkerboard(32, 40, 0.1);  // unbiased, noisy
  auto biased = reference * torch::tensor({0.7f, 0.9f, 1.2f}).view({1, 3, 1, 1});
  auto corrected = matchLocalMean(biased, render, 2.0);
  // Replicated edges break the checkerboard's zero mean within 3 sigma of the border.
  auto interior = [](const torch::Tensor& t) { return t.narrow(2, 6, 20).narrow(3, 6, 28); };
  const double before = interior(biased - reference).abs().max().item<double>();
  const double after = interior(corrected - reference).abs().max().item<double>();
  CHECK(before > 0.1);
  CHECK(after < 1e-3);
  CHECK((corrected - reference).abs().mean().item<double>() <
        0.2 * (biased - reference).abs().mean().item<double>());
  // Off: the image is returned as it is.
  CHECK(torch::equal(matchLocalMean(biased, render, 0.0), biased));
}

TEST_CASE(
    "matchLocalMean scales detail at most maxRatio, adds the rest of the mean, survives NaN") {
  // The network returned a tenth of the render with some detail: the detail is
  // scaled by the clamped ratio 4, the rest of the local mean comes as an offset.
  auto denoised = torch::full({1, 3, 8, 8}, 0.1f);
  denoised[0][0][4][4] = 0.2f;
  auto render = torch::full({1, 3, 8, 8}, 5.0f);
  const auto matched = matchLocalMean(denoised, render, 2.0);
  CHECK(matched[0][1].mean().item<double>() == doctest::Approx(5.0).epsilon(1e-5));
  const double detail = (matched[0][0][4][4] - matched[0][0][0][0]).item<double>();
  CHECK(detail > 0.0);
  CHECK(detail <= 4.0 * 0.1 + 1e-5);

  // A channel the network zeroed, where the render has light, comes back.
  auto zeroed = torch::full({1, 3, 8, 8}, 0.3f);
  zeroed[0][2].zero_();
  const auto restored = matchLocalMean(zeroed, torch::full({1, 3, 8, 8}, 0.3f), 0.25);
  CHECK(restored[0][2].min().item<double>() == doctest::Approx(0.3).epsilon(1e-4));
  // Never negative, even where the network is far brighter than the render.
  CHECK(matchLocalMean(torch::full({1, 3, 8, 8}, 5.0f), torch::full({1, 3, 8, 8}, 0.01f), 2.0)
            .min()
            .item<double>() >= 0.0);

  render[0][0][3][3] = std::numeric_limits<float>::quiet_NaN();
  render[0][1][4][4] = std::numeric_limits<float>::infinity();
  CHECK(torch::isfinite(matchLocalMean(denoised, render, 2.0)).all().item<bool>());
}

TEST_CASE("matchLocalMean spreads an isolated firefly instead of bringing it back") {
  const auto flat = torch::full({1, 3, 16, 16}, 0.1f);
  auto render = flat.clone();
  render[0][0][8][8] = 5.0f;  // one pixel far above all its neighbours
  const auto matched = matchLocalMean(flat, render, 0.25);
  CHECK(matched[0][0][8][8].item<double>() < 0.5);  // no sparkle
  CHECK(matched[0][0].sum().item<double>() ==
        doctest::Approx(render[0][0].sum().item<double>()).epsilon(1e-3));  // its energy stays

  // Two bright pixels side by side are a feature, not a firefly: kept.
  render[0][0][8][9] = 5.0f;
  CHECK(matchLocalMean(flat, render, 0.25)[0][0][8][8].item<double>() ==
        doctest::Approx(5.0).epsilon(1e-3));
}

TEST_CASE("keepBlack: black where the render is black over the window, nowhere else") {
  auto render = torch::zeros({1, 3, 10, 10});
  render.narrow(3, 5, 5).fill_(0.3);  // lit right half
  render[0][1][2][7] = 0.0f;          // one channel of a lit pixel is 0
  render[0][0][6][7] = 0.0f;          // a lone black pixel in the light (a 4-spp zero)
  render[0][1][6][7] = 0.0f;
  render[0][2][6][7] = 0.0f;
  auto denoised = torch::full({1, 3, 10, 10}, 1e-3);  // the network's haze, and light
  denoised.narrow(3, 5, 5).fill_(0.29);
  const auto out = keepBlack(denoised, render, 3);
  CHECK(out.narrow(3, 0, 4).abs().max().item<double>() == 0.0);        // black, away from the light
  CHECK(torch::equal(out.narrow(3, 4, 6), denoised.narrow(3, 4, 6)));  // light and its border
  // NaN counts as black, Inf as light.
  render[0][0][1][1] = std::numeric_limits<float>::quiet_NaN();
  render[0][0][8][1] = std::numeric_limits<float>::infinity();
  const auto odd = keepBlack(denoised, render, 3);
  CHECK(odd[0][0][1][1].item<double>() == 0.0);
  CHECK(odd[0][0][8][1].item<double>() == doctest::Approx(1e-3));
  // A wider window asks for more black around: 5x5 keeps column 3's haze.
  CHECK(keepBlack(denoised, render, 5)[0][0][5][3].item<double>() == doctest::Approx(1e-3));
  CHECK(keepBlack(denoised, render, 5)[0][0][5][2].item<double>() == 0.0);
  // At least 512 samples: 3x3 from 64 spp up, 7x7 at 16, 13x13 at 4 or unknown.
  CHECK(blackWindow(512) == 3);
  CHECK(blackWindow(64) == 3);
  CHECK(blackWindow(16) == 7);
  CHECK(blackWindow(4) == 13);
  CHECK(blackWindow(0) == 13);
  CHECK(blackWindow(1) == 23);
}

TEST_CASE("restoreHighlights keeps lights above the range, not isolated fireflies") {
  auto render = torch::full({1, 3, 12, 12}, 0.5);
  render.narrow(2, 2, 4).narrow(3, 2, 4).fill_(20.0);  // a 4x4 light
  render[0][0][9][9] = 50.0;                           // a firefly, red only
  auto denoised = render.clamp_max(6.0);               // the model's clipped output
  denoised[0][0][9][9] = 0.5;                          // with the firefly removed
  const auto out = restoreHighlights(denoised, render, 6.0);
  CHECK(out[0][1][3][3].item<double>() == 20.0);  // inside the light
  CHECK(out[0][2][2][2].item<double>() == 20.0);  // its corner: eroded, then dilated back
  CHECK(out[0][0][9][9].item<double>() == 0.5);   // the firefly stays removed
  CHECK(torch::equal(out.narrow(3, 7, 5), denoised.narrow(3, 7, 5)));
  // A one-pixel line above the range, which the network also clipped: kept,
  // with the render's colour instead of a hue shifted by the per-channel clip.
  auto line = torch::full({1, 3, 12, 12}, 0.5);
  line.narrow(3, 6, 1).select(1, 0).fill_(4.0);
  line.narrow(3, 6, 1).select(1, 2).fill_(9.0);
  auto clipped = line.clamp_max(6.0) * 0.995;
  const auto lineOut = restoreHighlights(clipped, line, 6.0);
  CHECK(lineOut[0][2][5][6].item<double>() == 9.0);
  CHECK(lineOut[0][0][5][6].item<double>() == 4.0);
  CHECK(torch::equal(lineOut.narrow(3, 0, 6), clipped.narrow(3, 0, 6)));
  // Below the range nothing changes; NaN and Inf in the render do not leak.
  CHECK(torch::equal(restoreHighlights(denoised, render, 25.0), denoised));
  render[0][1][3][3] = std::numeric_limits<float>::quiet_NaN();
  render.narrow(2, 2, 4).narrow(3, 2, 4)[0][2] = std::numeric_limits<float>::infinity();
  CHECK(torch::isfinite(restoreHighlights(denoised, render, 6.0)).all().item<bool>());
}
