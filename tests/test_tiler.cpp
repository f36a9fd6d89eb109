#include "doctest_torch.h"

#include "dn/model_inputs.h"
#include "dn/tiler.h"

using namespace dn;

namespace {

// A local operator with receptive-field radius 2 (two 3x3 convolutions).
torch::Tensor localOperator(const std::vector<torch::Tensor>& in) {
  torch::manual_seed(3);
  auto w1 = torch::randn({4, 3, 3, 3}), w2 = torch::randn({2, 4, 3, 3});
  auto h = torch::conv2d(in[0], w1, {}, 1, 1).tanh();
  return torch::conv2d(h, w2, {}, 1, 1) + in[1].narrow(1, 0, 1);
}

}  // namespace

TEST_CASE("tiles cover the frame with the requested overlap") {
  Tiler tiler(100, 70, 32, 8);
  int64_t covered = 0;
  for (const auto& r : tiler.tiles()) {
    CHECK(r.height == 32);
    CHECK(r.y0 + r.height <= 100);
    CHECK(r.x0 + r.width <= 70);
    covered += r.height * r.width;
  }
  CHECK(covered >= 100 * 70);
  CHECK(tiler.exactMargin() == 2);
  CHECK(Tiler(50, 40, 0, 16).tiles().size() == 1);
  CHECK(Tiler(50, 40, 64, 16).tiles().size() == 1);
}

TEST_CASE("tiled output equals the untiled output for a local operator") {
  torch::manual_seed(0);
  auto x = torch::randn({2, 3, 61, 47}), aux = torch::randn({2, 5, 61, 47});
  auto full = localOperator({x, aux});
  for (int64_t tile : {16, 24, 40}) {
    Tiler tiler(61, 47, tile, 8);  // margin 2 = the operator's radius
    auto tiled = tiler.apply({x, aux}, localOperator);
    CAPTURE(tile);
    CHECK(tiled.sizes() == full.sizes());
    CHECK((tiled - full).abs().max().item<float>() < 1e-5);
  }
  // Too small an overlap for the receptive field: seams appear.
  auto seamy = Tiler(61, 47, 16, 2).apply({x, aux}, localOperator);
  CHECK((seamy - full).abs().max().item<float>() > 1e-3);
}

TEST_CASE("memory-bounded tile sizes") {
  CHECK(tileSizeForMemory(1e9, 1000.0, 16) == 992);  // sqrt(1e6) = 1000 -> 992
  CHECK(tileSizeForMemory(10.0, 1000.0, 16) == 16);
}

TEST_CASE("radiance tonemapping is clamped to [0, 6] and exactly invertible") {
  auto v = torch::tensor({-1.0f, 0.0f, 0.5f, 3.0f, 6.0f, 100.0f, NAN}).view({1, 1, 1, 7});
  for (auto curve : {tonemap::Curve::Log, tonemap::Curve::Gamma}) {
    auto t = tonemapRadiance(v, curve);
    auto back = inverseTonemapRadiance(t, curve);
    auto expected = torch::tensor({0.0f, 0.0f, 0.5f, 3.0f, 6.0f, 6.0f, 0.0f}).view({1, 1, 1, 7});
    CHECK(torch::allclose(back, expected, 1e-5, 1e-5));
  }
  CHECK(tonemapRadiance(torch::full({1}, 6.0f), tonemap::Curve::Log).item<float>() ==
        doctest::Approx(0.51 * std::log(7.0)));
}

TEST_CASE("aux normalization keeps every buffer in a bounded range") {
  const auto& buffers = defaultAuxBuffers();
  const int64_t channels = auxChannelCount(buffers);
  CHECK(channels == 3 + 3 + 1 + 9 * 3);
  auto aux = torch::randn({1, channels, 4, 4}) * 1e4;
  auto n = normalizeAux(aux, buffers, tonemap::Curve::Log);
  CHECK(n.sizes() == aux.sizes());
  CHECK(n.min().item<float>() >= -1.0f);
  CHECK(n.max().item<float>() <= 1.0f);
  CHECK_THROWS_AS(normalizeAux(aux.narrow(1, 0, 5), buffers, tonemap::Curve::Log), std::invalid_argument);
  CHECK_THROWS_AS(auxChannelCount({"color"}), std::invalid_argument);
}
