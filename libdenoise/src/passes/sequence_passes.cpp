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
  // The view-dependent lights and their tints, read in one decoding of the file.
  std::vector<std::pair<std::string, std::string>> lights;  // light, its tint ("": none)
  std::map<std::string, std::size_t> index;                 // pass -> its image below
  std::vector<std::vector<std::string>> groups;
  auto want = [&](const std::string& key) {
    if (key.empty() || index.count(key)) return;
    index[key] = groups.size();
    groups.push_back(layout.channels.at(key));
  };
  for (const LightPassTerm& term : layout.terms)
    for (const std::string& key : term.lights)
      if (const LightPassSpec* spec = layout.rule->find(key); spec && spec->viewDependent) {
        lights.emplace_back(key, term.color);
        want(key);
        want(term.color);
      }
  if (lights.empty()) return Image();
  const std::vector<Image> images = readImages(path, groups, frame.dataWindow);
  for (const Image& image : images)  // readLightPasses names a wrong size, when asked for
    if (!image.sameShape(color)) return Image();
  Image moving(color.width, color.height, 1), all(color.width, color.height, 1);
  for (const auto& [key, tintKey] : lights) {
    const Image& light = images[index.at(key)];
    const Image* tint = tintKey.empty() ? nullptr : &images[index.at(tintKey)];
    for (std::size_t i = 0; i < color.pixelCount(); ++i)
      for (int c = 0; c < 3; ++c) {
        const float v =
            finiteOr0(light.pixels[3 * i + c]) * (tint ? finiteOr0(tint->pixels[3 * i + c]) : 1.0f);
        moving.pixels[i] += std::max(v, 0.0f) / 3;
      }
  }
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
