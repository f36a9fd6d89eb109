#include <algorithm>
#include <cmath>
#include <set>

#include "dn/io/buffer_io.h"
#include "dn/motion/motion.h"

namespace dn::motion {

namespace {

// Two channels (a, b) of an interleaved image as lookup offsets (sx * a, sy * b).
Image offsets(const Image& source, int a, int b, float sx, float sy) {
  Image out(source.width, source.height, 2);
  for (std::size_t i = 0; i < source.pixelCount(); ++i) {
    out.pixels[2 * i] = sx * source.pixels[i * source.channels + a];
    out.pixels[2 * i + 1] = sy * source.pixels[i * source.channels + b];
  }
  return out;
}

Image negated(const Image& image) {
  Image out = image;
  for (float& v : out.pixels) v = -v;
  return out;
}

}  // namespace

MotionField decodeBlenderVector(const Image& xyzw) {
  if (xyzw.channels != 4) throw std::invalid_argument("Blender's Vector pass has 4 channels");
  // Measured (testdata/motion): a camera move of (+3, +2) px (x right, y up)
  // from the previous frame and (+6, +4) px to the next writes X,Y = (3, 2) and
  // Z,W = (6, 4): the surface moved by (-3, -2) and (-6, -4) on screen, so
  // X,Y = p_previous - p and Z,W = p - p_next, y up. Rows run down: y flips.
  MotionField field;
  field.toPrevious = offsets(xyzw, 0, 1, 1.0f, -1.0f);
  field.toNext = offsets(xyzw, 2, 3, -1.0f, 1.0f);
  return field;
}

MotionField decodeForward(const Image& forward) {
  if (forward.channels < 2) throw std::invalid_argument("forward motion needs 2 channels");
  MotionField field;
  field.toNext = offsets(forward, 0, 1, 1.0f, -1.0f);
  field.toPrevious = negated(field.toNext);
  field.mirrored = true;
  return field;
}

MotionField decodeBackFore(const Image& back, const Image& fore) {
  if (back.channels < 2 || fore.channels < 2)
    throw std::invalid_argument("motionBack and motionFore need 2 channels each");
  MotionField field;
  field.toPrevious = offsets(back, 0, 1, 1.0f, -1.0f);
  field.toNext = offsets(fore, 0, 1, 1.0f, -1.0f);
  return field;
}

std::optional<MotionChannels> findMotionChannels(const std::vector<std::string>& names,
                                                 const std::string& viewLayer) {
  const std::set<std::string> have(names.begin(), names.end());
  std::vector<std::string> prefixes;
  if (!viewLayer.empty()) prefixes.push_back(viewLayer + ".");
  // Blender's single view layer: whatever stands before ".Vector.X".
  for (const auto& n : names) {
    const std::string tail = ".Vector.X";
    if (n.size() > tail.size() && n.compare(n.size() - tail.size(), tail.size(), tail) == 0)
      prefixes.push_back(n.substr(0, n.size() - tail.size() + 1));
  }
  prefixes.push_back("");
  auto all = [&](const std::string& base, std::vector<std::string> suffixes) {
    for (auto& s : suffixes) s = base + "." + s;
    const bool found = std::all_of(suffixes.begin(), suffixes.end(),
                                   [&](const std::string& s) { return have.count(s) != 0; });
    return found ? suffixes : std::vector<std::string>{};
  };
  auto pair = [&](const std::string& base) {
    for (const auto& s : {std::vector<std::string>{"X", "Y"}, {"x", "y"}, {"R", "G"}, {"r", "g"}})
      if (auto found = all(base, s); !found.empty()) return found;
    return std::vector<std::string>{};
  };
  for (const auto& prefix : prefixes) {
    if (auto c = all(prefix + "Vector", {"X", "Y", "Z", "W"}); !c.empty())
      return MotionChannels{Convention::BlenderVector, c, {}};
    auto back = pair(prefix + "motionBack"), fore = pair(prefix + "motionFore");
    if (!back.empty() && !fore.empty()) return MotionChannels{Convention::BackFore, back, fore};
    for (const char* name : {"motionvector", "motionvectors", "VRayVelocity", "velocity"})
      if (auto c = pair(prefix + name); !c.empty())
        return MotionChannels{Convention::ForwardPixels, c, {}};
  }
  return std::nullopt;
}

namespace {

std::string describe(const MotionChannels& found) {
  const std::string& first = found.channels.front();
  const std::string layer = first.substr(0, first.rfind('.'));
  switch (found.convention) {
    case Convention::BlenderVector:
      return layer + " (Blender's Vector: to the previous and the next frame, pixels, y up)";
    case Convention::BackFore:
      return layer + " and motionFore (RenderMan: to the previous and the next frame, pixels)";
    case Convention::ForwardPixels:
      return layer +
             " (motion to the next frame in pixels, y up, as Arnold, V-Ray and Karma document it; "
             "the previous frame taken as its mirror)";
  }
  return layer;
}

// A separate motion file without known names: 4 channels as Blender writes
// them, 2 or 3 as forward motion.
std::optional<MotionChannels> unnamedChannels(const std::vector<std::string>& names) {
  if (names.size() == 4) return MotionChannels{Convention::BlenderVector, names, {}};
  if (names.size() == 2 || names.size() == 3)
    return MotionChannels{Convention::ForwardPixels, {names[0], names[1]}, {}};
  return std::nullopt;
}

}  // namespace

MotionField decodeMotion(const MotionChannels& found, const std::vector<Image>& read, int width,
                         int height, const std::string& path) {
  for (const Image& group : read) {  // RenderMan's motionFore too
    if (group.width != width || group.height != height)
      throw IoError(path + ": the motion is " + std::to_string(group.width) + "x" +
                    std::to_string(group.height) + " but the frame is " + std::to_string(width) +
                    "x" + std::to_string(height));
    for (float v : group.pixels)
      if (!std::isfinite(v)) throw IoError(path + ": the motion holds NaN or Inf values");
  }
  const Image& first = read.front();
  MotionField field;
  switch (found.convention) {
    case Convention::BlenderVector:
      field = decodeBlenderVector(first);
      break;
    case Convention::ForwardPixels:
      field = decodeForward(first);
      break;
    case Convention::BackFore:
      field = decodeBackFore(first, read.back());
      break;
  }
  field.source = path + ": motion from " + describe(found);
  return field;
}

std::optional<MotionField> readMotion(const std::string& path, int width, int height,
                                      const std::string& viewLayer, bool separate) {
  const std::vector<std::string> names = channelNames(path);
  std::optional<MotionChannels> found = findMotionChannels(names, viewLayer);
  if (!found && separate) found = unnamedChannels(names);
  if (!found) {
    if (separate)
      throw IoError(path +
                    ": no motion channels (Vector.X/Y/Z/W, motionvector, VRayVelocity, "
                    "motionBack/motionFore, or 2 to 4 plain channels)");
    return std::nullopt;
  }
  return decodeMotion(*found, readImages(path, found->groups()), width, height, path);
}

}  // namespace dn::motion
