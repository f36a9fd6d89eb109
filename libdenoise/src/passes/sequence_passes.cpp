#include "dn/passes/sequence_passes.h"

#include "dn/io/buffer_io.h"

namespace dn {

namespace {

bool filteredOverTime(const LightPassLayout& layout, const std::string& key,
                      PassesOverTime overTime) {
  if (overTime == PassesOverTime::Off) return false;
  const LightPassSpec* spec = layout.rule->find(key);
  return overTime == PassesOverTime::All || !(spec && spec->isColor);
}

}  // namespace

temporal::Sequence::MakeCompanions lightPassCompanions(const OidnBase& base,
                                                       const SequencePassOptions& options) {
  return [base, options](const std::string& path, const FrameBuffers& frame) {
    const LightPassLayout layout = passLayoutOfFrame(path, frame);
    PassDenoiseOptions apart = options.denoise;
    // The sum closes it on the filtered passes; only a sharing rule reads it.
    apart.residualAlone = apart.share != ShareRule::None;
    const LightPassImages passes =
        denoisePassesApart(base, frame, layout, readLightPasses(path, layout, frame), apart);
    temporal::Companions companions;
    for (const auto& [key, image] : passes)
      companions[key] = {image,
                         key != kResidualPass && filteredOverTime(layout, key, options.overTime)};
    return companions;
  };
}

PassesResult passesOfSequenceFrame(const std::string& path, const FrameBuffers& frame,
                                   const std::map<std::string, Image>& filtered,
                                   const Image& denoisedBeauty,
                                   const SequencePassOptions& options) {
  PassesResult result;
  result.layout = passLayoutOfFrame(path, frame);
  // Only a sharing rule reads the noisy passes.
  const LightPassImages noisy = options.denoise.share == ShareRule::None
                                    ? LightPassImages()
                                    : readLightPasses(path, result.layout, frame);
  result.denoised = shareToBeauty(result.layout, noisy, filtered, denoisedBeauty, options.denoise);
  result.layers = denoisedPassLayers(result.layout, result.denoised.passes);
  return result;
}

}  // namespace dn
