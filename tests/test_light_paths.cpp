// The light-path split (dn/infer/light_paths.h): its arithmetic on made-up
// buffers, and what it buys on committed Cycles renders with every light pass.
#include "doctest_torch.h"

#include <cmath>
#include <limits>

#include "dn/infer/denoiser.h"
#include "dn/infer/light_paths.h"
#include "dn/io/buffer_io.h"
#include "dn/metrics.h"

using namespace dn;

namespace {

FrameBuffers frameOf(int w, int h) {
  FrameBuffers frame;
  frame.width = w;
  frame.height = h;
  for (const char* name : {"color", "diffuse_direct", "diffuse_indirect", "diffuse_color"})
    frame.buffers[name] = Image(w, h, 3);
  return frame;
}

double reinhardPsnr(const Image& a, const Image& reference) {
  return metrics::compare(reference, a, {"psnr"}).values.at("psnr");
}

}  // namespace

TEST_CASE("the diffuse part and the rest sum to the render") {
  FrameBuffers frame = frameOf(4, 1);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  // Pixel 0: an ordinary mix; 1: a diffuse colour above 1 (clamped as an
  // albedo); 2: more diffuse than the render holds (rounding in the passes);
  // 3: NaN in the passes and the colour.
  const float color[4] = {2.0f, 1.0f, 0.1f, nan};
  const float direct[4] = {1.0f, 0.5f, 0.4f, nan};
  const float indirect[4] = {0.5f, 0.25f, 0.0f, 0.3f};
  const float albedo[4] = {0.8f, 1.5f, 0.5f, 0.5f};
  for (int x = 0; x < 4; ++x)
    for (int c = 0; c < 3; ++c) {
      frame.buffers["color"].at(x, 0, c) = color[x];
      frame.buffers["diffuse_direct"].at(x, 0, c) = direct[x];
      frame.buffers["diffuse_indirect"].at(x, 0, c) = indirect[x];
      frame.buffers["diffuse_color"].at(x, 0, c) = albedo[x];
    }
  REQUIRE(hasDiffusePasses(frame));
  const LightPathSplit split = splitDiffuse(frame);
  const float diffuse[4] = {1.2f, 0.75f, 0.2f, 0.15f};
  const float rest[4] = {0.8f, 0.25f, 0.0f, 0.0f};
  for (int x = 0; x < 4; ++x)
    for (int c = 0; c < 3; ++c) {
      CAPTURE(x);
      CHECK(split.diffuse.at(x, 0, c) == doctest::Approx(diffuse[x]));
      CHECK(split.rest.at(x, 0, c) == doctest::Approx(rest[x]));
    }
  frame.buffers.erase("diffuse_indirect");
  CHECK_FALSE(hasDiffusePasses(frame));
  CHECK_THROWS_AS(splitDiffuse(frame), std::out_of_range);
}

TEST_CASE("with Cycles' diffuse passes -q high beats the prefilter mode alone") {
  const Denoiser denoiser = Denoiser::fromFile(std::string(DN_SOURCE_DIR) + "/models/default.dnm");
  DenoiseOptions whole, high;
  setQuality(whole, Quality::Balanced);
  setQuality(high, Quality::High);
  double gain = 0;
  int frames = 0;
  for (const char* scene : {"101", "102", "103", "104", "105", "106"}) {
    const std::string stem = std::string(DN_TESTDATA) + "/pairs/scene000" + scene;
    const FrameBuffers frame = readFrame(stem + "_4spp.exr");
    const Image reference = readImage(stem + "_ref.exr", 3);
    const DenoiseResult split = denoiser.denoise(frame, high);
    const DenoiseResult plain = denoiser.denoise(frame, whole);
    CHECK(split.lightPathsSplit);
    CHECK_FALSE(plain.lightPathsSplit);
    CHECK(split.buffersUsed.size() == 6);
    const double d = reinhardPsnr(split.color, reference) - reinhardPsnr(plain.color, reference);
    MESSAGE("scene000" << scene << ": " << d << " dB");
    CHECK(d > -0.05);  // measured +0.05 to +0.88 dB
    gain += d;
    ++frames;
  }
  MESSAGE("mean gain " << gain / frames << " dB");
  CHECK(gain / frames > 0.2);  // measured +0.40 dB
}

TEST_CASE("without the diffuse passes the result is the prefiltered base's, bit for bit") {
  const Denoiser denoiser = Denoiser::fromFile(std::string(DN_SOURCE_DIR) + "/models/default.dnm");
  FrameBuffers frame = readFrame(std::string(DN_TESTDATA) + "/pairs/scene000104_4spp.exr");
  frame.buffers.erase("diffuse_color");
  DenoiseOptions high, whole;
  setQuality(high, Quality::High);
  setQuality(whole, Quality::Balanced);
  const DenoiseResult a = denoiser.denoise(frame, high);
  const DenoiseResult b = denoiser.denoise(frame, whole);
  CHECK_FALSE(a.lightPathsSplit);
  CHECK(a.prefiltered);
  CHECK(a.color.pixels == b.color.pixels);
}

TEST_CASE("the base and the default read the diffuse passes where they can split") {
  const std::vector<std::string> cycles = {"color",         "albedo",         "normal",
                                           "depth",         "diffuse_direct", "diffuse_indirect",
                                           "diffuse_color", "glossy_direct"};
  for (const char* model : {"oidn.dnm", "default.dnm"}) {
    CAPTURE(model);
    const Denoiser denoiser = Denoiser::fromFile(std::string(DN_SOURCE_DIR) + "/models/" + model);
    const auto usable = denoiser.usableBuffers(cycles);
    for (const auto& name : diffusePassBuffers())
      CHECK(std::count(usable.begin(), usable.end(), name) == 1);
    // Without the normal there is no prefilter mode, so no split.
    const auto noNormal = denoiser.usableBuffers(
        {"color", "albedo", "diffuse_direct", "diffuse_indirect", "diffuse_color"});
    CHECK(noNormal == std::vector<std::string>{"color", "albedo"});
  }
}
