#include "dn/passes/sequence_passes.h"

#include <algorithm>
#include <cmath>

#include "dn/infer/oidn_pipeline.h"
#include "dn/io/buffer_io.h"

namespace dn {

using temporal::Companion;

namespace {

float finiteOr0(float v) { return std::isfinite(v) ? v : 0.0f; }

bool filteredOverTime(const LightPassLayout& layout, const std::string& key,
                      PassesOverTime overTime) {
  if (overTime == PassesOverTime::Off) return false;
  const LightPassSpec* spec = layout.rule->find(key);
  return overTime == PassesOverTime::All || !(spec && spec->isColor);
}

}  // namespace

temporal::CompanionMaker lightPassCompanions(const OidnBase& base,
                                             const SequencePassOptions& options) {
  PassDenoiseOptions apart = options.denoise;
  // The sum closes it on the filtered passes; only a sharing rule reads it.
  apart.residualAlone = apart.share != ShareRule::None;
  // The accumulated renders are denoised with the first-hit albedo.
  const bool again = options.accumulated && apart.guide == LightPassGuide::Albedo;
  temporal::CompanionMaker maker;
  maker.make = [base, options, apart, again](const std::string& path, const FrameBuffers& frame) {
    const LightPassLayout layout = passLayoutOfFrame(path, frame);
    const LightPassImages noisy = readLightPasses(path, layout, frame);
    const LightPassImages passes = denoisePassesApart(base, frame, layout, noisy, apart);
    temporal::Companions companions;
    for (const auto& [key, image] : passes) {
      Companion& companion = companions[key];
      companion.image = image;
      companion.overTime = key != kResidualPass && filteredOverTime(layout, key, options.overTime);
      const LightPassSpec* spec = layout.rule->find(key);
      companion.viewDependent = spec && spec->viewDependent;
      if (again && companion.overTime && spec && !spec->isColor) companion.render = noisy.at(key);
    }
    return companions;
  };
  if (again)
    maker.denoiseAccumulated = [base, apart](const FrameBuffers& guides,
                                             const std::map<std::string, Image>& accumulated) {
      const FrameBuffers clean =
          guides.auxPrefiltered ? guides : withCleanAux(base, guides, apart.run, apart.run);
      std::map<std::string, Image> out;
      for (const auto& [key, render] : accumulated)
        out[key] =
            denoiseLight(base, render, clean.get("albedo"), clean.get("normal"), apart.run, false);
      return out;
    };
  return maker;
}

Image viewDependentShare(const std::string& path, const FrameBuffers& frame, int radius) {
  const LightPassLayout layout = findLightPasses(channelNames(path), layerPrefixOf(frame));
  const Image& color = frame.get("color");
  Image moving(color.width, color.height, 1), all(color.width, color.height, 1);
  bool found = false;
  for (const LightPassTerm& term : layout.terms) {
    const Image tint =
        term.color.empty() ? Image() : readImage(path, 3, layout.channels.at(term.color));
    if (!tint.empty() && !tint.sameShape(color)) return Image();
    for (const std::string& key : term.lights) {
      const LightPassSpec* spec = layout.rule->find(key);
      if (!spec || !spec->viewDependent) continue;
      const Image light = readImage(path, 3, layout.channels.at(key));
      if (!light.sameShape(color)) return Image();  // readLightPasses names it, when asked for
      for (std::size_t i = 0; i < color.pixelCount(); ++i)
        for (int c = 0; c < 3; ++c) {
          const float v = finiteOr0(light.pixels[3 * i + c]) *
                          (tint.empty() ? 1.0f : finiteOr0(tint.pixels[3 * i + c]));
          moving.pixels[i] += std::max(v, 0.0f) / 3;
        }
      found = true;
    }
  }
  if (!found) return Image();
  for (std::size_t i = 0; i < color.pixelCount(); ++i)
    for (int c = 0; c < 3; ++c)
      all.pixels[i] += std::max(finiteOr0(color.pixels[3 * i + c]), 0.0f) / 3;
  moving = boxMean(moving, radius), all = boxMean(all, radius);
  for (std::size_t i = 0; i < moving.pixels.size(); ++i)
    moving.pixels[i] =
        all.pixels[i] > 0.0f ? std::clamp(moving.pixels[i] / all.pixels[i], 0.0f, 1.0f) : 0.0f;
  return moving;
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
