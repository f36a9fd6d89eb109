// The additive light passes renderers write for compositing, and each
// renderer's rule for adding them back up to the beauty. A compositor
// regrades the passes and recombines them; the denoised passes
// (dn/passes/joint_denoise.h) keep that rule exact. What a file lacks is
// covered by a residual: the beauty minus what its passes explain.
#pragma once

#include <map>
#include <string>
#include <vector>

#include "dn/image.h"
#include "dn/io/buffers.h"

namespace dn {

// One pass a renderer writes.
struct LightPassSpec {
  std::string key;                  // renderer-independent name, e.g. "diffuse_direct"
  std::vector<std::string> layers;  // layer names tried in order, e.g. "DiffDir", "Diffuse Direct"
  bool isColor = false;             // a colour (albedo-like) pass that multiplies light passes
  // Reflected or refracted light: it moves with the view and the light, not
  // with the surface the motion vectors follow.
  bool viewDependent = false;
};

// One term of the sum: the light passes added, times the colour pass when
// there is one. Cycles' diffuse term: (DiffDir + DiffInd) x DiffCol.
struct LightPassTerm {
  std::string name;                 // e.g. "diffuse"
  std::vector<std::string> lights;  // keys of the light passes
  std::string color;                // key of the colour pass, "" for none
};

// A renderer's passes and rule: beauty = sum over terms.
struct LightPassRule {
  std::string renderer;      // "Cycles"
  std::string beauty;        // the beauty's name in the formula: "Combined"
  std::string documentedBy;  // where the rule is documented
  std::string residual;      // the residual's pass name: "Residual"
  std::string outputPrefix;  // what goes in front of a pass's layer name in the denoised
                             // pass's name: "Denoised " (Cycles: "Denoised Diffuse Direct")
  std::vector<LightPassSpec> passes;
  std::vector<LightPassTerm> terms;

  const LightPassSpec* find(const std::string& key) const;  // nullptr when unknown
};

// The rules this toolkit knows, in the order they are tried: Cycles (Blender
// 3.x short names and 4.x/5.x full names), Arnold's built-in LPE AOVs.
const std::vector<LightPassRule>& lightPassRules();

// The passes of one rule found in a file.
struct LightPassLayout {
  const LightPassRule* rule = nullptr;
  std::string viewLayerPrefix;  // "ViewLayer." for Blender, "" for none
  // Key -> the file's layer name without the view layer ("DiffDir",
  // "Diffuse Direct") and its three channels.
  std::map<std::string, std::string> layers;
  std::map<std::string, std::vector<std::string>> channels;
  // Terms whose light passes are written with their colour pass (or need none);
  // each term lists only the light passes the file has.
  std::vector<LightPassTerm> terms;
  // One line each: passes found that the rule cannot use (a light pass without
  // its colour pass), for -v.
  std::vector<std::string> notes;

  bool empty() const { return terms.empty(); }
  // The file's layer name of a key; the rule's residual name for the residual.
  std::string layerName(const std::string& key) const;
  // The rule as the file's passes spell it, e.g.
  // "Combined = (DiffDir + DiffInd) x DiffCol + Emit + Residual".
  std::string formula() const;
  // Every key used (lights and colours of the terms), in rule order.
  std::vector<std::string> usedKeys() const;
};

// The key of the residual pass in LightPassImages.
inline constexpr char kResidualPass[] = "residual";

// Finds the rule with the most usable terms among the file's channel names
// (dn::channelNames) under `viewLayerPrefix` ("ViewLayer." or ""); ties go to
// the earlier rule. Empty when no term is usable.
LightPassLayout findLightPasses(const std::vector<std::string>& channelNames,
                                const std::string& viewLayerPrefix);

// The passes' pixels by key, plus the residual (kResidualPass): the beauty
// minus the sum of the terms.
using LightPassImages = std::map<std::string, Image>;

// Reads the passes of `layout` from `path` in the frame's size (throws IoError
// naming the file when a pass has another size) and adds the residual of the
// frame's colour. Non-finite values are read as 0.
LightPassImages readLightPasses(const std::string& path, const LightPassLayout& layout,
                                const FrameBuffers& frame);

// The rule's sum of `passes` (the residual included when present), in the
// order a compositor adds them: per term (lights added, then times the colour),
// terms in rule order, the residual last.
Image recombine(const LightPassLayout& layout, const LightPassImages& passes);

// The largest per-pixel relative difference |a - b| / max(|b|, floor) over
// all channels; `floor` keeps black pixels from dividing by zero.
double maxRelativeDifference(const Image& a, const Image& b, double floor = 1e-3);

}  // namespace dn
