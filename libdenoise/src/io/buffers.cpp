#include "dn/io/buffers.h"

#include <algorithm>
#include <stdexcept>

namespace dn {

const std::vector<BufferSpec>& canonicalBuffers() {
  // Layer names are tried in order, in the chosen view layer (Blender) or at
  // the top level. Where they come from (docs/dndenoise.md has the table):
  //   Blender/Cycles 3.x: Combined, Denoising Albedo/Normal/Depth, DiffDir, ...
  //   Blender 5 (and 4.x that writes full names): Diffuse Direct, Glossy
  //     Indirect, Transmission Color, Emission, Environment, one part each;
  //   Arnold: RGBA, albedo / denoise_albedo, N, Z, diffuse_albedo,
  //     specular_albedo, transmission_albedo, emission, background;
  //   RenderMan: Ci, albedo, normal / Nn, z / zfiltered;
  //   Karma/Mantra (Houdini): C, albedo, N, Pz;
  //   V-Ray: plain RGB, VRayDiffuseFilter (the albedo its denoisers take),
  //     VRayNormals, VRayBumpNormals;
  //   Redshift: plain RGB, DiffuseFilter, N / BumpNormals, Z;
  //   pbrt-v4 (gbuffer film): R,G,B, Albedo, Ns (shading normal), Variance;
  //   Mitsuba 3 (aov integrator, names as its docs use them): R,G,B,
  //     albedo, nn / sh_normal (X,Y,Z), dd.y / depth (T).
  // Other renderers' light-path AOVs (Arnold diffuse_direct and
  // transmission_direct, Karma directdiffuse, ...) include the surface colour,
  // which Cycles' light passes do not (Cycles: diffuse = (DiffDir + DiffInd) x
  // DiffCol), so they are not taken for Cycles' passes; --channels maps them
  // where they match.
  static const std::vector<BufferSpec> specs = {
      {"color",
       3,
       // Cycles writes "Noisy Image" when its own denoiser ran: Combined is
       // then already denoised.
       {"Noisy Image", "Combined", "", "rgba", "RGBA", "beauty", "Beauty", "color", "Ci", "C"},
       "noisy radiance (HDR, linear)"},
      {"albedo",
       3,
       {"Denoising Albedo", "albedo", "Albedo", "denoise_albedo", "alb", "VRayDiffuseFilter",
        "DiffuseFilter"},
       "first-hit albedo"},
      {"normal",
       3,
       {"Denoising Normal", "Normal", "normal", "Ns", "N", "Nn", "nn", "sh_normal", "normals",
        "VRayNormals", "VRayBumpNormals", "BumpNormals", "nrm"},
       "first-hit normal"},
      {"depth",
       1,
       {"Denoising Depth", "Depth", "depth", "dd.y", "Z", "z", "zfiltered", "Pz"},
       "camera distance"},
      {"diffuse_direct", 3, {"DiffDir", "Diffuse Direct"}, "direct diffuse light"},
      {"diffuse_indirect", 3, {"DiffInd", "Diffuse Indirect"}, "indirect diffuse light"},
      {"diffuse_color",
       3,
       {"DiffCol", "Diffuse Color", "diffuse_color", "diffuse_albedo"},
       "diffuse colour"},
      {"glossy_direct", 3, {"GlossDir", "Glossy Direct", "glossy_direct"}, "direct glossy light"},
      {"glossy_indirect",
       3,
       {"GlossInd", "Glossy Indirect", "glossy_indirect"},
       "indirect glossy light"},
      {"glossy_color",
       3,
       {"GlossCol", "Glossy Color", "glossy_color", "specular_albedo"},
       "glossy colour"},
      {"transmission_direct", 3, {"TransDir", "Transmission Direct"}, "direct transmitted light"},
      {"transmission_indirect",
       3,
       {"TransInd", "Transmission Indirect"},
       "indirect transmitted light"},
      {"transmission_color",
       3,
       {"TransCol", "Transmission Color", "transmission_color", "transmission_albedo"},
       "transmission colour"},
      {"emission", 3, {"Emit", "Emission", "emission"}, "emitted light"},
      {"environment",
       3,
       {"Env", "Environment", "environment", "background"},
       "directly visible environment"},
      {"roughness", 1, {"roughness", "Roughness"}, "shader AOV: roughness"},
      {"metallic", 1, {"metallic", "Metallic"}, "shader AOV: metallic"},
      {"transmission", 1, {"transmission", "Transmission"}, "shader AOV: transmission weight"},
      {"color_variance",
       3,
       {"Variance", "variance", "color_variance"},
       "per-pixel variance of color"},
  };
  return specs;
}

const BufferSpec* findBufferSpec(const std::string& name) {
  for (const auto& spec : canonicalBuffers())
    if (spec.name == name) return &spec;
  return nullptr;
}

const std::vector<std::string>& defaultAuxBuffers() {
  static const std::vector<std::string> buffers = {"albedo",
                                                   "normal",
                                                   "depth",
                                                   "diffuse_direct",
                                                   "diffuse_indirect",
                                                   "diffuse_color",
                                                   "glossy_direct",
                                                   "glossy_indirect",
                                                   "glossy_color",
                                                   "transmission_direct",
                                                   "transmission_indirect",
                                                   "transmission_color"};
  return buffers;
}

const Image& FrameBuffers::get(const std::string& name) const {
  auto it = buffers.find(name);
  if (it == buffers.end()) throw std::out_of_range("frame has no '" + name + "' buffer");
  return it->second;
}

std::vector<std::string> FrameBuffers::names() const {
  std::vector<std::string> out;
  for (const auto& spec : canonicalBuffers())  // canonical order, not map order
    if (has(spec.name)) out.push_back(spec.name);
  return out;
}

FrameBuffers withUnread(const FrameBuffers& frame, const std::vector<std::string>& names) {
  std::vector<std::string> wanted;
  for (const auto& name : names)
    if (std::find(frame.unread.begin(), frame.unread.end(), name) != frame.unread.end())
      wanted.push_back(name);
  FrameBuffers more = frame;
  if (wanted.empty() || !frame.readUnread) return more;
  for (auto& [name, image] : frame.readUnread(wanted)) {
    more.buffers[name] = std::move(image);
    more.unread.erase(std::find(more.unread.begin(), more.unread.end(), name));
  }
  return more;
}

std::string layerPrefixOf(const FrameBuffers& frame, const std::string& buffer) {
  auto it = frame.sourceChannels.find(buffer);
  return it == frame.sourceChannels.end() ? "" : layerPrefixOf(it->second);
}

std::string layerPrefixOf(const std::vector<std::string>& sourceChannels) {
  if (sourceChannels.empty()) return "";
  const std::string& channel = sourceChannels.front();
  auto lastDot = channel.rfind('.');
  if (lastDot == std::string::npos) return "";
  auto layerDot = channel.rfind('.', lastDot - 1);  // "ViewLayer.Combined.R" -> "ViewLayer."
  return layerDot == std::string::npos ? "" : channel.substr(0, layerDot + 1);
}

}  // namespace dn
