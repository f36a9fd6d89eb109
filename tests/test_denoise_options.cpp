// What a caller asks of the Denoiser (dn/infer/denoise_options.h): quality
// levels as settings of the default pipeline, and exposures the networks can take.
#include "doctest_torch.h"

#include <string>

#include "dn/infer/denoiser.h"
#include "dn/io/buffer_io.h"

using namespace dn;

namespace {

const std::string kExample = std::string(DN_TESTDATA) + "/pairs/scene000104_4spp.exr";

Denoiser defaultModel() {
  return Denoiser::fromFile(std::string(DN_SOURCE_DIR) + "/models/default.dnm");
}

}  // namespace

TEST_CASE("quality names and what each level runs") {
  CHECK(qualityFromName("fast") == Quality::Fast);
  CHECK(qualityFromName("balanced") == Quality::Balanced);
  CHECK(qualityFromName("high") == Quality::High);
  CHECK_FALSE(qualityFromName("High"));
  CHECK_FALSE(qualityFromName(""));

  const Denoiser denoiser = defaultModel();
  const FrameBuffers frame = readFrame(kExample);
  struct Expected {
    Quality quality;
    bool prefiltered, split;
    int64_t steps;
  };
  for (const Expected& e :
       {Expected{Quality::Fast, false, false, 1}, Expected{Quality::Balanced, true, false, 3},
        Expected{Quality::High, true, true, 6}}) {
    CAPTURE(int(e.quality));
    DenoiseOptions options;
    options.control = ControlUse::Never;
    setQuality(options, e.quality);
    const DenoiseResult result = denoiser.denoise(frame, options);
    CHECK(result.prefiltered == e.prefiltered);
    CHECK(result.lightPathsSplit == e.split);
    CHECK(result.steps == e.steps);
  }
  // The default options are the high level.
  DenoiseOptions high;
  setQuality(high, Quality::High);
  const DenoiseOptions defaults;
  CHECK(defaults.prefilter == high.prefilter);
  CHECK(defaults.lightPaths == high.lightPaths);
}

TEST_CASE("exposures within 100 times the autoexposure either way, no further") {
  CHECK_NOTHROW(checkExposure(0.0, 4.0));  // automatic
  CHECK_NOTHROW(checkExposure(4.0, 4.0));
  CHECK_NOTHROW(checkExposure(400.0, 4.0));
  CHECK_NOTHROW(checkExposure(0.04, 4.0));
  CHECK_THROWS_AS(checkExposure(401.0, 4.0), std::invalid_argument);
  CHECK_THROWS_AS(checkExposure(0.0399, 4.0), std::invalid_argument);
  CHECK_THROWS_AS(checkExposure(1e-30, 4.0), std::invalid_argument);

  const Denoiser denoiser = defaultModel();
  const FrameBuffers frame = readFrame(kExample);
  DenoiseOptions options;
  options.exposure = 1e-30;
  CHECK_THROWS_WITH_AS(denoiser.denoise(frame, options),
                       doctest::Contains("times the frame's autoexposure"), std::invalid_argument);
  options.control = ControlUse::Always;  // the Control Module's path checks it too
  CHECK_THROWS_AS(denoiser.denoise(frame, options), std::invalid_argument);
}
