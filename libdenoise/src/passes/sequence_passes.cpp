#include "dn/passes/sequence_passes.h"

#include <algorithm>
#include <cmath>

#include "dn/infer/device.h"
#include "dn/infer/oidn_pipeline.h"
#include "dn/io/buffer_io.h"

namespace dn {

using temporal::Companion;

namespace {

float finiteOr0(float v) { return std::isfinite(v) ? v : 0.0f; }

// Whether `key` is the colour pass of a term whose light moves with the view
// (Glossy Color): it changes with the view as that light does.
bool colorOfViewDependentLight(const LightPassLayout& layout, const std::string& key) {
  for (const LightPassTerm& term : layout.terms)
    if (term.color == key)
      for (const std::string& light : term.lights)
        if (const LightPassSpec* spec = layout.rule->find(light); spec && spec->viewDependent)
          return true;
  return false;
}

bool filteredOverTime(const LightPassLayout& layout, const std::string& key,
                      PassesOverTime overTime) {
  if (overTime == PassesOverTime::Off) return false;
  const LightPassSpec* spec = layout.rule->find(key);
  if (overTime == PassesOverTime::All || !(spec && spec->isColor)) return true;
  return !colorOfViewDependentLight(layout, key);
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
    maker.denoiseAccumulated = [base, apart, precision = options.accumulatedPrecision](
                                   const FrameBuffers& guides,
                                   const std::map<std::string, Image>& accumulated) {
      useNetworkPrecision(base, apart.precision);
      const FrameBuffers clean =
          guides.auxPrefiltered ? guides : withCleanAux(base, guides, apart.run, apart.run);
      useNetworkPrecision(base, precision);
      std::map<std::string, Image> out;
      for (const auto& [key, render] : accumulated)
        out[key] =
            denoiseLight(base, render, clean.get("albedo"), clean.get("normal"), apart.run, false);
      return out;
    };
  return maker;
}

Precision secondDenoisingPrecision(Precision precision, const torch::Device& device,
                                   bool precisionGiven) {
  const bool faster = device.is_cpu() && cpuComputesBFloat16();
  return precision == Precision::Float && faster && !precisionGiven ? Precision::BFloat16
                                                                    : precision;
}

namespace {

// The view-dependent lights of a file's passes, each with its tint ("": none),
// and the channels of each pass they need, by FrameBuffers::extra's name.
struct ViewDependentLights {
  std::vector<std::pair<std::string, std::string>> lights;
  ChannelGroups channels;
};

const std::string kExtraPrefix = "view-dependent ";

ViewDependentLights viewDependentLights(const std::string& path, const std::string& layerPrefix) {
  const LightPassLayout layout = findLightPasses(channelNames(path), layerPrefix);
  ViewDependentLights out;
  auto want = [&](const std::string& key) {
    if (!key.empty()) out.channels[kExtraPrefix + key] = layout.channels.at(key);
  };
  for (const LightPassTerm& term : layout.terms)
    for (const std::string& key : term.lights)
      if (const LightPassSpec* spec = layout.rule->find(key); spec && spec->viewDependent) {
        out.lights.emplace_back(key, term.color);
        want(key);
        want(term.color);
      }
  return out;
}

}  // namespace

ChannelGroups viewDependentChannels(const std::string& path, const std::string& layerPrefix) {
  return viewDependentLights(path, layerPrefix).channels;
}

Image viewDependentShare(const std::string& path, const FrameBuffers& frame, int radius) {
  const auto [lights, channels] = viewDependentLights(path, layerPrefixOf(frame));
  if (lights.empty()) return Image();
  const Image& color = frame.get("color");
  // The passes as read with the frame (ReadOptions::extra), else in one decoding now.
  std::map<std::string, const Image*> images;
  std::vector<std::string> missing;
  std::vector<std::vector<std::string>> groups;
  for (const auto& [name, group] : channels)
    if (auto it = frame.extra.find(name); it != frame.extra.end())
      images[name] = &it->second;
    else
      missing.push_back(name), groups.push_back(group);
  const std::vector<Image> read =
      groups.empty() ? std::vector<Image>() : readImages(path, groups, frame.dataWindow);
  for (std::size_t k = 0; k < missing.size(); ++k) images[missing[k]] = &read[k];
  for (const auto& entry : images)  // readLightPasses names a wrong size, when asked for
    if (!entry.second->sameShape(color)) return Image();
  Image moving(color.width, color.height, 1), all(color.width, color.height, 1);
  for (const auto& [key, tintKey] : lights) {
    const Image& light = *images.at(kExtraPrefix + key);
    const Image* tint = tintKey.empty() ? nullptr : images.at(kExtraPrefix + tintKey);
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
