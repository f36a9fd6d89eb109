// The render split by light path, where the renderer wrote its light passes
// (Cycles: Diffuse Direct, Diffuse Indirect and Diffuse Color). The diffuse
// part is its colour times its light; the rest (glossy, transmission,
// emission, background, volumes) is what remains of the render. The base
// denoises each part with its own guide, the diffuse colour for the diffuse
// part, and the two results, summed, are averaged with the whole render's:
// two estimates whose errors differ (docs/dndenoise.md#light-paths).
#pragma once

#include <string>
#include <vector>

#include "dn/image.h"
#include "dn/io/buffers.h"

namespace dn {

// The buffers the split reads beside the colour.
const std::vector<std::string>& diffusePassBuffers();

// Whether `frame` holds every buffer of diffusePassBuffers().
bool hasDiffusePasses(const FrameBuffers& frame);

struct LightPathSplit {
  Image diffuse;  // diffuse_color * (diffuse_direct + diffuse_indirect), RGB
  Image rest;     // color - diffuse, clamped at 0, RGB
};

// Splits the frame's colour (NaN and negatives as 0; the diffuse colour
// clamped to [0, 1] as an albedo). Throws std::out_of_range when a pass is
// missing (see hasDiffusePasses).
LightPathSplit splitDiffuse(const FrameBuffers& frame);

// The image mirrored about its diagonal (x and y swapped): the split's parts
// are denoised transposed, so that the network's errors there differ more
// from its errors on the whole.
Image transposed(const Image& image);

}  // namespace dn
