#include "doctest_torch.h"

#include <algorithm>
#include <cmath>

#include "dn/infer/oidn_filter.h"
#include "dn/infer/tiler.h"
#include "dn/nn/model_inputs.h"

using namespace dn;

namespace {

// A local operator with receptive-field radius 2 (two 3x3 convolutions).
torch::Tensor localOperator(const std::vector<torch::Tensor>& in) {
  torch::manual_seed(3);
  auto w1 = torch::randn({4, 3, 3, 3}), w2 = torch::randn({2, 4, 3, 3});
  auto h = torch::conv2d(in[0], w1, {}, 1, 1).tanh();
  return torch::conv2d(h, w2, {}, 1, 1) + in[1].narrow(1, 0, 1);
}

// A frame with the default aux buffers: wide-ranged random values, some NaN/Inf.
FrameBuffers randomFrame(int width, int height) {
  torch::manual_seed(7);
  FrameBuffers frame;
  frame.width = width;
  frame.height = height;
  for (const auto& name : defaultAuxBuffers()) {
    Image image(width, height, findBufferSpec(name)->channels);
    auto values = torch::randn({static_cast<int64_t>(image.size())}) * 50.0;
    std::copy_n(values.data_ptr<float>(), image.size(), image.pixels.begin());
    image.pixels[3] = NAN;
    image.pixels[image.size() / 2] = INFINITY;
    frame.buffers[name] = image;
  }
  return frame;
}

// The frame's aux buffers as one (1,C,H,W) tensor, element by element.
torch::Tensor auxByLoops(const FrameBuffers& frame) {
  auto out = torch::empty({1, auxChannelCount(defaultAuxBuffers()), frame.height, frame.width});
  auto a = out.accessor<float, 4>();
  int64_t channel = 0;
  for (const auto& name : defaultAuxBuffers()) {
    const Image& image = frame.get(name);
    for (int c = 0; c < image.channels; ++c, ++channel)
      for (int y = 0; y < image.height; ++y)
        for (int x = 0; x < image.width; ++x) a[0][channel][y][x] = image.at(x, y, c);
  }
  return out;
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

TEST_CASE("full-height columns: fewer pixels run than squares, the same blend") {
  torch::manual_seed(1);
  auto x = torch::randn({1, 3, 40, 90}), aux = torch::randn({1, 5, 40, 90});
  const Tiler columns(40, 90, 40, 32, 8), squares(40, 90, 32, 8);
  for (const auto& r : columns.tiles()) CHECK((r.y0 == 0 && r.height == 40 && r.width == 32));
  CHECK(columns.tiles().size() == 4);  // starts 0, 24, 48, 58
  CHECK(tiledPixels(columns) == 4 * 40 * 32);
  CHECK(tiledPixels(columns) < tiledPixels(squares));
  const auto full = localOperator({x, aux});
  CHECK((columns.apply({x, aux}, localOperator) - full).abs().max().item<float>() < 1e-5);
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
  CHECK_THROWS_AS(normalizeAux(aux.narrow(1, 0, 5), buffers, tonemap::Curve::Log),
                  std::invalid_argument);
  CHECK_THROWS_AS(auxChannelCount({"color"}), std::invalid_argument);
}

TEST_CASE("aux normalized per region equals the whole frame's normalized aux, cropped") {
  const FrameBuffers frame = randomFrame(13, 11);
  const auto curve = tonemap::Curve::Log;
  const auto whole = normalizeAux(auxByLoops(frame), defaultAuxBuffers(), curve);
  for (const TileRect r : {TileRect{0, 0, 11, 13}, TileRect{2, 5, 6, 4}, TileRect{10, 12, 1, 1}}) {
    auto region =
        normalizedAuxRegion(frame, defaultAuxBuffers(), curve, r.y0, r.x0, r.height, r.width);
    CAPTURE(r.y0);
    CAPTURE(r.x0);
    REQUIRE(region.sizes() == crop(whole, r).sizes());
    CHECK(torch::equal(region, crop(whole, r)));
  }
  FrameBuffers lacking = frame;
  lacking.buffers.erase("depth");
  CHECK_THROWS_AS(normalizedAuxRegion(lacking, defaultAuxBuffers(), curve, 0, 0, 2, 2),
                  std::out_of_range);
}

TEST_CASE("image regions are copies, one channel included") {
  Image image(5, 4, 1);
  for (std::size_t i = 0; i < image.size(); ++i) image.pixels[i] = static_cast<float>(i);
  auto region = imageRegionToTensor(image, 1, 2, 3, 2);
  CHECK(region.sizes() == torch::IntArrayRef({1, 1, 3, 2}));
  CHECK(region[0][0][0][0].item<float>() == image.at(2, 1, 0));
  CHECK(region[0][0][2][1].item<float>() == image.at(3, 3, 0));
  region.fill_(-1.0f);
  CHECK(image.at(2, 1, 0) == 7.0f);
}

TEST_CASE("tiles built from their rectangles equal the untiled output") {
  const FrameBuffers frame = randomFrame(47, 61);
  const auto curve = tonemap::Curve::Log;
  torch::manual_seed(1);
  auto x = torch::randn({1, 3, 61, 47});
  auto full = localOperator({x, normalizeAux(auxByLoops(frame), defaultAuxBuffers(), curve)});
  for (int64_t tile : {16, 40, 64}) {
    Tiler tiler(61, 47, tile, 8);  // margin 2 = the operator's radius
    auto tiled = tiler.apply([&](const TileRect& r) {
      return localOperator({crop(x, r), normalizedAuxRegion(frame, defaultAuxBuffers(), curve, r.y0,
                                                            r.x0, r.height, r.width)});
    });
    CAPTURE(tile);
    REQUIRE(tiled.sizes() == full.sizes());
    CHECK((tiled - full).abs().max().item<float>() < 1e-5);
  }
}

TEST_CASE("OIDN's tiles: the CPU's budget and cap, or a GPU's share of its free memory") {
  // The large network of the prefilter mode, the one that decides the tiles at 4K.
  const double bytesPerPixel =
      oidnBytesPerPixel(OidnUNetConfig{OidnArch::Large, 9, 3, false, false});
  const int64_t blend = 4 * kOidnOverlapLarge;
  OidnRunOptions cpu;  // 3 GB and OIDN's 2160x2160 cap
  const Tiler cpuTiles = planOidnTiles(2160, 3840, bytesPerPixel, blend, cpu);
  CHECK(cpuTiles.tiles().size() == 5);  // full-height columns, as docs/dndenoise.md says
  CHECK(cpuTiles.tiles().front().height == 2160);
  CHECK(planOidnTiles(1080, 1920, bytesPerPixel, blend, cpu).tiles().size() == 1);

  OidnRunOptions gpu;
  gpu.maxTilePixels = 0;
  gpu.maxMemoryBytes = deviceMemoryBudget(100e9);  // a large GPU, mostly free
  CHECK(gpu.maxMemoryBytes == doctest::Approx(kDeviceBudgetShare * 100e9));
  CHECK(planOidnTiles(2160, 3840, bytesPerPixel, blend, gpu).tiles().size() == 1);
  // The same budget with OIDN's CPU cap: tiled, as before.
  OidnRunOptions capped = gpu;
  capped.maxTilePixels = kOidnMaxTilePixels;
  CHECK(planOidnTiles(2160, 3840, bytesPerPixel, blend, capped).tiles().size() > 1);
  // A small GPU's budget tiles 4K; nothing free, the smallest tiles, never none.
  gpu.maxMemoryBytes = deviceMemoryBudget(8e9);
  const Tiler small = planOidnTiles(2160, 3840, bytesPerPixel, blend, gpu);
  CHECK(small.tiles().size() > 1);
  for (const TileRect& r : small.tiles())
    CHECK(double(r.height) * r.width * bytesPerPixel <= gpu.maxMemoryBytes);
  CHECK(deviceMemoryBudget(-1.0) == 0.0);
  gpu.maxMemoryBytes = deviceMemoryBudget(0.0);
  CHECK(planOidnTiles(2160, 3840, bytesPerPixel, blend, gpu).tiles().size() > 100);
  // An explicit tile size wins over every budget.
  gpu.tile = 1024;
  CHECK(planOidnTiles(2160, 3840, bytesPerPixel, blend, gpu).tiles().front().width == 1024);
}
