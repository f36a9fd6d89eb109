#include "dn/io/buffers.h"

#include <stdexcept>

namespace dn {

const std::vector<BufferSpec>& canonicalBuffers() {
  // Layer names are tried in order: Blender/Cycles first, then common names
  // used by other renderers and by oidnDenoise-style pipelines.
  static const std::vector<BufferSpec> specs = {
      {"color",
       3,
       // Cycles writes "Noisy Image" when its own denoiser ran: Combined is
       // then already denoised.
       {"Noisy Image", "Combined", "", "rgba", "RGBA", "beauty", "color", "Ci"},
       "noisy radiance (HDR, linear)"},
      {"albedo", 3, {"Denoising Albedo", "albedo", "Albedo", "alb"}, "first-hit albedo"},
      {"normal", 3, {"Denoising Normal", "normal", "Normal", "N", "nrm"}, "first-hit normal"},
      {"depth", 1, {"Denoising Depth", "Depth", "depth", "Z"}, "camera distance"},
      {"diffuse_direct", 3, {"DiffDir", "diffuse_direct"}, "direct diffuse light"},
      {"diffuse_indirect", 3, {"DiffInd", "diffuse_indirect"}, "indirect diffuse light"},
      {"diffuse_color", 3, {"DiffCol", "diffuse_color", "diffuse_albedo"}, "diffuse colour"},
      {"glossy_direct", 3, {"GlossDir", "glossy_direct", "specular_direct"}, "direct glossy light"},
      {"glossy_indirect",
       3,
       {"GlossInd", "glossy_indirect", "specular_indirect"},
       "indirect glossy light"},
      {"glossy_color", 3, {"GlossCol", "glossy_color", "specular_albedo"}, "glossy colour"},
      {"transmission_direct", 3, {"TransDir", "transmission_direct"}, "direct transmitted light"},
      {"transmission_indirect",
       3,
       {"TransInd", "transmission_indirect"},
       "indirect transmitted light"},
      {"transmission_color", 3, {"TransCol", "transmission_color"}, "transmission colour"},
      {"emission", 3, {"Emit", "emission"}, "emitted light"},
      {"environment", 3, {"Env", "environment", "background"}, "directly visible environment"},
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

std::string layerPrefixOf(const FrameBuffers& frame, const std::string& buffer) {
  auto it = frame.sourceChannels.find(buffer);
  if (it == frame.sourceChannels.end() || it->second.empty()) return "";
  const std::string& channel = it->second.front();
  auto lastDot = channel.rfind('.');
  if (lastDot == std::string::npos) return "";
  auto layerDot = channel.rfind('.', lastDot - 1);  // "ViewLayer.Combined.R" -> "ViewLayer."
  return layerDot == std::string::npos ? "" : channel.substr(0, layerDot + 1);
}

}  // namespace dn
