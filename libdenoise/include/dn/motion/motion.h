// Screen-space motion vectors: where each pixel's surface is in the previous
// and the next frame, read from the passes renderers write.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "dn/image.h"

namespace dn::motion {

// Motion of one frame as lookup offsets in pixels, image coordinates (x to the
// right, y down, as rows are stored): the surface seen at pixel (x, y) of this
// frame is at (x + dx, y + dy) in the neighbouring frame. Two channels each.
struct MotionField {
  Image toPrevious;
  Image toNext;
  std::string source;  // one line: the channels and the convention they were read in
  // The renderer wrote the motion to one neighbour only; the other is its
  // negation (constant velocity), which the round-trip check then verifies.
  bool mirrored = false;

  bool empty() const { return toPrevious.empty() || toNext.empty(); }
  int width() const { return toNext.width; }
  int height() const { return toNext.height; }
};

// How a renderer's motion pass is laid out (docs/dndenoise.md, "Motion vectors").
enum class Convention {
  // Cycles "Vector" (X, Y, Z, W): X,Y = p_previous - p, Z,W = p - p_next, in
  // pixels with y up. Established with renders of a known camera move in
  // Blender 3.4 and 5.0 (tests/test_motion.cpp, testdata/motion/).
  BlenderVector,
  // The motion to the next frame only, in pixels with y up: Arnold's
  // "motionvector" AOV (VECTOR2), V-Ray's VRayVelocity render element (R, G;
  // B is depth motion), Karma's "motionvector" render var. From their manuals,
  // not from renders made here.
  ForwardPixels,
  // RenderMan's "motionBack" and "motionFore" outputs: p_previous - p and
  // p_next - p in pixels with y up. From its manual, not from renders made here.
  BackFore,
};

// Decodes Cycles' four-channel Vector pass (interleaved X, Y, Z, W).
MotionField decodeBlenderVector(const Image& xyzw);
// Decodes a two- (or more) channel forward motion pass (R = x, G = y up).
MotionField decodeForward(const Image& forward);
// Decodes RenderMan's back and fore passes (R = x, G = y up, each).
MotionField decodeBackFore(const Image& back, const Image& fore);

// The motion channels a file holds, from its channel names alone: the first
// convention found, its channels in order. Empty when the file has none.
struct MotionChannels {
  Convention convention = Convention::BlenderVector;
  std::vector<std::string> channels;   // Blender: X, Y, Z, W; forward: x, y; RenderMan: back x, y
  std::vector<std::string> channels2;  // RenderMan: fore x, y
  // The groups to read (each one image): channels, then channels2 if any.
  std::vector<std::vector<std::string>> groups() const {
    return channels2.empty() ? std::vector<std::vector<std::string>>{channels}
                             : std::vector<std::vector<std::string>>{channels, channels2};
  }
};
std::optional<MotionChannels> findMotionChannels(const std::vector<std::string>& channelNames,
                                                 const std::string& viewLayer = "");

// The motion from `found`'s groups as read (MotionChannels::groups) of file
// `path`; throws dn::IoError naming the file when it is not width x height or
// holds NaN or Inf.
MotionField decodeMotion(const MotionChannels& found, const std::vector<Image>& read, int width,
                         int height, const std::string& path);

// The motion of a frame file (its motion pass), or of a separate motion file
// (`separate` = true: a file of just 4 or 2 channels is read as Blender's Vector
// or as forward motion when it has no known names). nullopt when the file has no
// motion; throws dn::IoError naming the file when it is unreadable or the
// motion is not width x height.
std::optional<MotionField> readMotion(const std::string& path, int width, int height,
                                      const std::string& viewLayer = "", bool separate = false);

}  // namespace dn::motion
