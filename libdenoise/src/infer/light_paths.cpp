#include "dn/infer/light_paths.h"

#include <algorithm>
#include <cmath>

namespace dn {
namespace {

float finiteOrZero(float v) { return std::isfinite(v) ? v : 0.0f; }

}  // namespace

const std::vector<std::string>& diffusePassBuffers() {
  static const std::vector<std::string> names = {"diffuse_direct", "diffuse_indirect",
                                                 "diffuse_color"};
  return names;
}

bool hasDiffusePasses(const FrameBuffers& frame) {
  return std::all_of(diffusePassBuffers().begin(), diffusePassBuffers().end(),
                     [&](const std::string& name) { return frame.has(name); });
}

LightPathSplit splitDiffuse(const FrameBuffers& frame) {
  const Image& color = frame.get("color");
  const Image& direct = frame.get("diffuse_direct");
  const Image& indirect = frame.get("diffuse_indirect");
  const Image& albedo = frame.get("diffuse_color");
  LightPathSplit split{Image(frame.width, frame.height, 3), Image(frame.width, frame.height, 3)};
  for (int y = 0; y < frame.height; ++y)
    for (int x = 0; x < frame.width; ++x)
      for (int c = 0; c < 3; ++c) {
        const float light = std::max(finiteOrZero(direct.at(x, y, c)), 0.0f) +
                            std::max(finiteOrZero(indirect.at(x, y, c)), 0.0f);
        const float diffuse = std::clamp(finiteOrZero(albedo.at(x, y, c)), 0.0f, 1.0f) * light;
        const float total = std::max(finiteOrZero(color.at(x, y, c)), 0.0f);
        split.diffuse.at(x, y, c) = diffuse;
        split.rest.at(x, y, c) = std::max(total - diffuse, 0.0f);
      }
  return split;
}

Image transposed(const Image& image) {
  Image out(image.height, image.width, image.channels);
  for (int y = 0; y < image.height; ++y)
    for (int x = 0; x < image.width; ++x)
      std::copy_n(image.pixel(x, y), image.channels, out.pixel(y, x));
  return out;
}

}  // namespace dn
