// The variants of the denoised light passes (dn/passes/joint_denoise.h), for
// choosing by measurement: each light pass's guide (its term's colour pass or
// the first-hit albedo) times each way of sharing the beauty's difference
// (by estimated error, by magnitude, none: the residual takes it), and the
// colour passes by OIDN's albedo network or guided by its large one. The beauty
// is dndenoise's default result. Writes OUTDIR/<guide>-<share>.exr with the
// channels <key>.R/G/B of every pass (float) and beauty.R/G/B.
//
//   passes_variants --model models/default.dnm IN.exr OUTDIR
#include <cstdio>
#include <string>
#include <vector>

#include "dn/infer/denoiser.h"
#include "dn/io/buffer_io.h"
#include "dn/passes/joint_denoise.h"

using namespace dn;

namespace {

void writePasses(const std::string& path, const LightPassImages& passes, const Image& beauty) {
  std::vector<std::pair<std::string, const Image*>> layers = {{"beauty", &beauty}};
  for (const auto& [key, image] : passes) layers.push_back({key, &image});
  Image packed(beauty.width, beauty.height, int(3 * layers.size()));
  std::vector<std::string> names;
  for (std::size_t l = 0; l < layers.size(); ++l) {
    for (const char* c : {"R", "G", "B"}) names.push_back(layers[l].first + "." + c);
    for (int y = 0; y < beauty.height; ++y)
      for (int x = 0; x < beauty.width; ++x)
        for (int c = 0; c < 3; ++c) packed.at(x, y, int(3 * l) + c) = layers[l].second->at(x, y, c);
  }
  writeImage(path, packed, false, names);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 5 || std::string(argv[1]) != "--model") {
    std::fprintf(stderr, "usage: passes_variants --model MODEL IN.exr OUTDIR\n");
    return 1;
  }
  const std::string model = argv[2], input = argv[3], outDir = argv[4];
  try {
    const FrameBuffers frame = readFrame(input);
    const Image beauty = Denoiser::fromFile(model).denoise(frame, DenoiseOptions{}).color;
    const OidnBase base = oidnBaseOfModel(model);
    const LightPassLayout layout = findLightPasses(channelNames(input), layerPrefixOf(frame));
    if (layout.empty()) throw IoError(input + ": has no light passes");
    const LightPassImages noisy = readLightPasses(input, layout, frame);
    std::printf("%s: %s\n", input.c_str(), layout.formula().c_str());
    struct Apart {
      std::string name;
      LightPassGuide guide;
      ColorPassDenoise colorPasses;
    };
    const std::vector<Apart> aparts = {
        {"color-alb", LightPassGuide::TermColor, ColorPassDenoise::AlbedoNetwork},
        {"albedo-alb", LightPassGuide::Albedo, ColorPassDenoise::AlbedoNetwork},
        {"color-guided", LightPassGuide::TermColor, ColorPassDenoise::Guided}};
    const std::vector<std::pair<std::string, ShareRule>> shares = {
        {"error", ShareRule::Error},
        {"magnitude", ShareRule::Magnitude},
        {"relnoise", ShareRule::RelativeNoise},
        {"none", ShareRule::None}};
    for (const auto& variant : aparts) {
      PassDenoiseOptions options;
      options.guide = variant.guide;
      options.colorPasses = variant.colorPasses;
      const LightPassImages apart = denoisePassesApart(base, frame, layout, noisy, options);
      for (const auto& [shareName, share] : shares) {
        options.share = share;
        const DenoisedPasses result = shareToBeauty(layout, noisy, apart, beauty, options);
        const std::string out = outDir + "/" + variant.name + "-" + shareName + ".exr";
        writePasses(out, result.passes, beauty);
        std::printf("%s: max relative recombination error %.3g\n", out.c_str(),
                    result.maxRelativeError);
      }
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "passes_variants: %s\n", e.what());
    return 1;
  }
  return 0;
}
