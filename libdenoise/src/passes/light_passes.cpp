#include "dn/passes/light_passes.h"

#include <algorithm>
#include <cmath>
#include <set>

#include "dn/io/buffer_io.h"

namespace dn {

namespace {

// Cycles: "Combined = (Diffuse Direct + Diffuse Indirect) x Diffuse Color +
// the same for glossy and transmission + Emission + Environment + Volume
// Direct + Volume Indirect". The light passes exclude the BSDF colour, which
// the colour passes hold (Blender manual, Render > Layers & Passes > Passes:
// "BSDF color is not included in this pass"; its "Combining" section; the
// Compositor's "Combine passes" figure). Blender 3.x writes the short names,
// 4.x and 5.x the full ones (one part per pass in Blender 5's multi-part files).
LightPassRule cyclesRule() {
  LightPassRule rule;
  rule.renderer = "Cycles";
  rule.beauty = "Combined";
  rule.documentedBy =
      "Blender manual, Render > Layers & Passes > Passes (docs.blender.org/manual/en/3.4/"
      "render/layers/passes.html)";
  rule.residual = "Residual";
  rule.outputPrefix = "Denoised ";
  rule.passes = {
      {"diffuse_direct", {"DiffDir", "Diffuse Direct"}, false},
      {"diffuse_indirect", {"DiffInd", "Diffuse Indirect"}, false},
      {"diffuse_color", {"DiffCol", "Diffuse Color"}, true},
      {"glossy_direct", {"GlossDir", "Glossy Direct"}, false, true},
      {"glossy_indirect", {"GlossInd", "Glossy Indirect"}, false, true},
      {"glossy_color", {"GlossCol", "Glossy Color"}, true},
      {"transmission_direct", {"TransDir", "Transmission Direct"}, false, true},
      {"transmission_indirect", {"TransInd", "Transmission Indirect"}, false, true},
      {"transmission_color", {"TransCol", "Transmission Color"}, true},
      {"volume_direct", {"VolumeDir", "Volume Direct"}, false},
      {"volume_indirect", {"VolumeInd", "Volume Indirect"}, false},
      {"emission", {"Emit", "Emission"}, false},
      {"environment", {"Env", "Environment"}, false},
  };
  rule.terms = {
      {"diffuse", {"diffuse_direct", "diffuse_indirect"}, "diffuse_color"},
      {"glossy", {"glossy_direct", "glossy_indirect"}, "glossy_color"},
      {"transmission", {"transmission_direct", "transmission_indirect"}, "transmission_color"},
      {"volume", {"volume_direct", "volume_indirect"}, ""},
      {"emission", {"emission"}, ""},
      {"environment", {"environment"}, ""},
  };
  return rule;
}

// Arnold's built-in light path expression AOVs split the beauty (RGBA, C.*)
// by the first scattering event seen from the camera: diffuse reflection
// C<RD> (direct C<RD>L, indirect C<RD>[DSVOB].*), specular reflection
// C<RS[^'coat']> (direct, indirect), coat C<RS'coat'>.*, specular
// transmission C<TS>.*, subsurface and diffuse transmission C<TD>.*, volume
// CV.*, emission C[LO] and background CB: disjoint paths, added as they are
// (Arnold User Guide, "Light Path Expression AOVs", built-in LPEs). They
// include the surface colour, so no term multiplies.
LightPassRule arnoldRule() {
  LightPassRule rule;
  rule.renderer = "Arnold";
  rule.beauty = "RGBA";
  rule.documentedBy =
      "Arnold User Guide, Light Path Expression AOVs (help.autodesk.com/view/ARNOL/ENU/"
      "?guid=arnold_user_guide_ac_output_aovs_ac_expression_aovs_html)";
  rule.residual = "residual";
  rule.outputPrefix = "denoised_";
  const std::vector<std::string> names = {"diffuse_direct",
                                          "diffuse_indirect",
                                          "specular_direct",
                                          "specular_indirect",
                                          "coat",
                                          "transmission",
                                          "sss",
                                          "volume",
                                          "emission",
                                          "background"};
  const std::set<std::string> viewDependent = {"specular_direct", "specular_indirect", "coat",
                                               "transmission"};
  for (const auto& name : names)
    rule.passes.push_back({"arnold_" + name, {name}, false, viewDependent.count(name) > 0});
  rule.terms = {
      {"diffuse", {"arnold_diffuse_direct", "arnold_diffuse_indirect"}, ""},
      {"specular", {"arnold_specular_direct", "arnold_specular_indirect"}, ""},
      {"coat", {"arnold_coat"}, ""},
      {"transmission", {"arnold_transmission"}, ""},
      {"sss", {"arnold_sss"}, ""},
      {"volume", {"arnold_volume"}, ""},
      {"emission", {"arnold_emission"}, ""},
      {"background", {"arnold_background"}, ""},
  };
  return rule;
}

// The three channels of layer `base` when the file has them.
std::vector<std::string> rgbChannels(const std::set<std::string>& names, const std::string& base) {
  for (const auto& suffixes : {std::vector<std::string>{"R", "G", "B"}, {"r", "g", "b"}}) {
    std::vector<std::string> channels;
    for (const auto& s : suffixes) channels.push_back(base + "." + s);
    if (std::all_of(channels.begin(), channels.end(),
                    [&](const std::string& c) { return names.count(c) != 0; }))
      return channels;
  }
  return {};
}

LightPassLayout layoutFor(const LightPassRule& rule, const std::set<std::string>& names,
                          const std::string& prefix) {
  LightPassLayout layout;
  layout.rule = &rule;
  layout.viewLayerPrefix = prefix;
  std::map<std::string, std::string> layers;
  std::map<std::string, std::vector<std::string>> channels;
  for (const auto& spec : rule.passes)
    for (const auto& layer : spec.layers) {
      auto found = rgbChannels(names, prefix + layer);
      if (found.empty()) continue;
      layers[spec.key] = layer;
      channels[spec.key] = std::move(found);
      break;
    }
  for (const auto& term : rule.terms) {
    LightPassTerm present{term.name, {}, term.color};
    for (const auto& light : term.lights)
      if (layers.count(light)) present.lights.push_back(light);
    if (present.lights.empty()) continue;
    if (!term.color.empty() && !layers.count(term.color)) {
      for (const auto& light : present.lights)
        layout.notes.push_back(layers[light] + " is not used: the file has no " +
                               rule.find(term.color)->layers.back() + " pass to multiply it");
      continue;
    }
    for (const auto& key : present.lights) {
      layout.layers[key] = layers[key];
      layout.channels[key] = channels[key];
    }
    if (!term.color.empty()) {
      layout.layers[term.color] = layers[term.color];
      layout.channels[term.color] = channels[term.color];
    }
    layout.terms.push_back(std::move(present));
  }
  return layout;
}

float finiteOrZero(float v) { return std::isfinite(v) ? v : 0.0f; }

}  // namespace

const LightPassSpec* LightPassRule::find(const std::string& key) const {
  for (const auto& spec : passes)
    if (spec.key == key) return &spec;
  return nullptr;
}

const std::vector<LightPassRule>& lightPassRules() {
  static const std::vector<LightPassRule> rules = {cyclesRule(), arnoldRule()};
  return rules;
}

std::string LightPassLayout::layerName(const std::string& key) const {
  if (key == kResidualPass) return rule ? rule->residual : "Residual";
  auto it = layers.find(key);
  return it == layers.end() ? key : it->second;
}

std::string LightPassLayout::formula() const {
  std::string sum;
  for (const auto& term : terms) {
    std::string lights;
    for (const auto& light : term.lights)
      lights += (lights.empty() ? "" : " + ") + layerName(light);
    if (!term.color.empty())
      lights =
          (term.lights.size() > 1 ? "(" + lights + ")" : lights) + " x " + layerName(term.color);
    sum += (sum.empty() ? "" : " + ") + lights;
  }
  return (rule ? rule->beauty : std::string("beauty")) + " = " + sum + " + " +
         layerName(kResidualPass);
}

std::vector<std::string> LightPassLayout::usedKeys() const {
  std::vector<std::string> keys;
  for (const auto& term : terms) {
    keys.insert(keys.end(), term.lights.begin(), term.lights.end());
    if (!term.color.empty()) keys.push_back(term.color);
  }
  return keys;
}

LightPassLayout findLightPasses(const std::vector<std::string>& channelNames,
                                const std::string& viewLayerPrefix) {
  const std::set<std::string> names(channelNames.begin(), channelNames.end());
  LightPassLayout best;
  for (const auto& rule : lightPassRules()) {
    LightPassLayout layout = layoutFor(rule, names, viewLayerPrefix);
    if (layout.terms.size() > best.terms.size()) best = std::move(layout);
  }
  return best;
}

LightPassImages readLightPasses(const std::string& path, const LightPassLayout& layout,
                                const FrameBuffers& frame) {
  LightPassImages passes;
  const std::vector<std::string> keys = layout.usedKeys();
  std::vector<std::vector<std::string>> groups;
  for (const auto& key : keys) groups.push_back(layout.channels.at(key));
  std::vector<Image> images = readImages(path, groups, frame.dataWindow);  // one decoding
  for (std::size_t k = 0; k < keys.size(); ++k) {
    const std::string& key = keys[k];
    Image& image = images[k];
    if (image.width != frame.width || image.height != frame.height)
      throw IoError(path + ": pass " + layout.layerName(key) + " is " +
                    std::to_string(image.width) + "x" + std::to_string(image.height) +
                    " but the colour is " + std::to_string(frame.width) + "x" +
                    std::to_string(frame.height));
    for (float& v : image.pixels) v = finiteOrZero(v);
    passes[key] = std::move(image);
  }
  const Image explained = recombine(layout, passes);
  const Image& color = frame.get("color");
  Image residual(frame.width, frame.height, 3);
  for (int y = 0; y < frame.height; ++y)
    for (int x = 0; x < frame.width; ++x)
      for (int c = 0; c < 3; ++c)
        residual.at(x, y, c) = finiteOrZero(color.at(x, y, c)) - explained.at(x, y, c);
  passes[kResidualPass] = std::move(residual);
  return passes;
}

Image recombine(const LightPassLayout& layout, const LightPassImages& passes) {
  if (passes.empty()) return Image();
  const Image& any = passes.begin()->second;
  Image sum(any.width, any.height, 3);
  const std::size_t n = sum.pixels.size();
  std::vector<float> term(n);
  for (const auto& t : layout.terms) {
    std::fill(term.begin(), term.end(), 0.0f);
    for (const auto& light : t.lights) {
      const auto& pixels = passes.at(light).pixels;
      for (std::size_t i = 0; i < n; ++i) term[i] += pixels[i];
    }
    if (!t.color.empty()) {
      const auto& color = passes.at(t.color).pixels;
      for (std::size_t i = 0; i < n; ++i) term[i] *= color[i];
    }
    for (std::size_t i = 0; i < n; ++i) sum.pixels[i] += term[i];
  }
  auto residual = passes.find(kResidualPass);
  if (residual != passes.end())
    for (std::size_t i = 0; i < n; ++i) sum.pixels[i] += residual->second.pixels[i];
  return sum;
}

double maxRelativeDifference(const Image& a, const Image& b, double floor) {
  double worst = 0;
  const std::size_t n = std::min(a.pixels.size(), b.pixels.size());
  for (std::size_t i = 0; i < n; ++i)
    worst = std::max(worst, std::abs(double(a.pixels[i]) - b.pixels[i]) /
                                std::max(std::abs(double(b.pixels[i])), floor));
  return worst;
}

}  // namespace dn
