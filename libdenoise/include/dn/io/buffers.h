// The canonical set of per-frame render buffers, independent of how a renderer
// names its channels. Buffer I/O (dn/buffer_io.h) fills it from files.
#pragma once

#include <functional>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "dn/image.h"

namespace dn {

// One canonical buffer: its name, channel count and how renderers name it.
struct BufferSpec {
  std::string name;                 // canonical name, e.g. "albedo"
  int channels;                     // 3 for colours and normals, 1 for scalars
  std::vector<std::string> layers;  // layer names tried in order, e.g. "Denoising Albedo", "albedo"
  std::string description;
};

// All canonical buffers, in a fixed order (the order model inputs use):
//   color, albedo, normal, depth,
//   diffuse_direct, diffuse_indirect, diffuse_color,
//   glossy_direct, glossy_indirect, glossy_color,
//   transmission_direct, transmission_indirect, transmission_color,
//   emission, environment, roughness, metallic, transmission, color_variance
const std::vector<BufferSpec>& canonicalBuffers();
const BufferSpec* findBufferSpec(const std::string& name);  // nullptr if unknown

// The default model's aux inputs: what Blender/Cycles writes with Denoising Data
// and the diffuse, glossy and transmission light passes (direct, indirect, colour).
const std::vector<std::string>& defaultAuxBuffers();

// A rectangle of pixels in a file's coordinates, as OpenEXR's data window (the
// pixels stored) and display window (the whole frame) are given.
struct PixelWindow {
  int x = 0;
  int y = 0;
  int width = 0;
  int height = 0;
  bool empty() const { return width <= 0 || height <= 0; }
  bool operator==(const PixelWindow& o) const {
    return x == o.x && y == o.y && width == o.width && height == o.height;
  }
  bool operator!=(const PixelWindow& o) const { return !(*this == o); }
};

// One frame's buffers by canonical name. Every image has the same width/height:
// the data window of the colour (a border render is smaller than its display
// window, an overscan render larger).
struct FrameBuffers {
  int width = 0;
  int height = 0;
  PixelWindow dataWindow;     // where the buffers' pixels sit in the frame
  PixelWindow displayWindow;  // the whole frame
  std::map<std::string, Image> buffers;
  // The channel groups of ReadOptions::extra, by the caller's names.
  std::map<std::string, Image> extra;
  // The colour's alpha (one channel), empty when the colour has none: the
  // result layer carries it.
  Image alpha;
  // One line each: what the reader assumed or decoded (e.g. normals stored as
  // (n + 1) / 2), for -v and the caller's warnings.
  std::vector<std::string> notes;
  // Where each buffer came from: the file's channel names, e.g.
  // {"ViewLayer.Combined.R", ...}; empty for synthesized buffers.
  std::map<std::string, std::vector<std::string>> sourceChannels;
  // Samples per pixel the renderer recorded in the file (Cycles writes
  // "cycles.<view layer>.samples"); 0 when unknown.
  int samplesPerPixel = 0;
  // The albedo and normal are the prefilter's already (DenoiseResult's
  // cleanAlbedo and cleanNormal of the same frame): a second, cheaper
  // denoising of the frame (its render accumulated over time) runs one network
  // on them, not the prefilter mode's three.
  bool auxPrefiltered = false;
  // Whether the colour's noise is correlated between pixels (a splatting
  // pixel filter), where known: a frame's render accumulated over time has
  // the noise of the frame, whose first denoising measured it, and is steered
  // as the frame was without measuring again. Unknown: measured where a
  // Control Module could steer (ControlUse::Auto).
  std::optional<bool> correlatedNoise;
  // The colour is a sequence's render accumulated over its window: the
  // frame's second denoising (dn/temporal/sequence.h).
  bool accumulated = false;
  // Buffers of the source left out of the first read, and how to read them
  // (dn/io/buffer_io.h sets both): a pipeline reads what only one of its paths
  // needs when it takes that path, e.g. the Control Module's extra buffers.
  std::vector<std::string> unread;
  std::function<std::map<std::string, Image>(const std::vector<std::string>&)> readUnread;

  bool has(const std::string& name) const { return buffers.count(name) != 0; }
  const Image& get(const std::string& name) const;  // throws std::out_of_range naming the buffer
  std::vector<std::string> names() const;
};

// `frame` with those of `names` it left unread read now (FrameBuffers::unread).
FrameBuffers withUnread(const FrameBuffers& frame, const std::vector<std::string>& names);

// The layer prefix the colour came from ("ViewLayer." for Blender, "" for plain
// RGB), so results can be written as a sibling pass: prefix + "Denoised".
std::string layerPrefixOf(const FrameBuffers& frame, const std::string& buffer = "color");
// The same from a buffer's channel names.
std::string layerPrefixOf(const std::vector<std::string>& sourceChannels);

}  // namespace dn
