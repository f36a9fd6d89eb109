// Motion vectors: each renderer convention's direction and sign, checked on
// renders of a known camera move (testdata/motion, made by
// experiments/render_sequences.py --scene convention); reprojection and the
// temporal filter on synthetic frames with known shifts and an occluder.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <limits>
#include <random>
#include <stdexcept>

#include "dn/io/buffer_io.h"
#include "dn/motion/motion.h"
#include "dn/motion/reproject.h"
#include "dn/temporal/temporal_filter.h"

using namespace dn;
using namespace dn::motion;

namespace {

const std::string kMotionDir = std::string(DN_TESTDATA) + "/motion/";

// The camera of the convention scene moves (+3, +2) px from frame 1 to 2 and
// (+6, +4) px from 2 to 3 (x right, y up in the view), so the surface moves
// the other way on screen. In image coordinates (rows run down) the surface at
// a pixel of frame 2 is at (+3, -2) from it in frame 1 and at (-6, +4) in frame 3.
constexpr float kToPrevious[2] = {3.0f, -2.0f};
constexpr float kToNext[2] = {-6.0f, 4.0f};

// Mean |a - b| over pixels where trust > 0, and the share of such pixels.
std::pair<double, double> trustedError(const Image& a, const Image& b, const Image& trust) {
  double sum = 0.0;
  std::size_t n = 0;
  for (std::size_t i = 0; i < trust.pixels.size(); ++i) {
    if (trust.pixels[i] <= 0.0f) continue;
    for (int c = 0; c < a.channels; ++c)
      sum += std::abs(a.pixels[i * a.channels + c] - b.pixels[i * b.channels + c]);
    ++n;
  }
  return {n ? sum / (n * a.channels) : 1e9, double(n) / trust.pixels.size()};
}

void checkConvention(const std::string& dir) {
  const std::string middle = kMotionDir + dir + "/spp4.0002.exr";
  const FrameBuffers f2 = readFrame(middle);
  auto field = readMotion(middle, f2.width, f2.height);
  REQUIRE(field);
  CHECK(field->source.find("Blender") != std::string::npos);
  // Decoded from its channels as read with the frame's buffers: the same.
  const auto found = findMotionChannels(channelNames(middle));
  REQUIRE(found);
  ReadOptions withMotion;
  withMotion.extra["motion"] = found->channels;
  const Image vector = readFrame(middle, withMotion).extra.at("motion");
  const MotionField decoded = decodeMotion(*found, {vector}, f2.width, f2.height, middle);
  CHECK(decoded.toNext.pixels == field->toNext.pixels);
  CHECK(decoded.toPrevious.pixels == field->toPrevious.pixels);
  for (std::size_t i = 0; i < field->toNext.pixelCount(); ++i) {
    REQUIRE(field->toPrevious.pixels[2 * i] == doctest::Approx(kToPrevious[0]).epsilon(0.01));
    REQUIRE(field->toPrevious.pixels[2 * i + 1] == doctest::Approx(kToPrevious[1]).epsilon(0.01));
    REQUIRE(field->toNext.pixels[2 * i] == doctest::Approx(kToNext[0]).epsilon(0.01));
    REQUIRE(field->toNext.pixels[2 * i + 1] == doctest::Approx(kToNext[1]).epsilon(0.01));
  }
  // Independent of the numbers above: the neighbours' albedo (a texture),
  // brought along the decoded motion, matches this frame's; along the
  // opposite sign it does not.
  for (int side : {-1, 1}) {
    const std::string other = kMotionDir + dir + (side < 0 ? "/spp4.0001.exr" : "/spp4.0003.exr");
    const FrameBuffers neighbour = readFrame(other);
    auto neighbourField = readMotion(other, f2.width, f2.height);
    REQUIRE(neighbourField);
    const Guides none;
    const Image positions = chainPositions({{&none, &*field}, {&none, &*neighbourField}}, side > 0);
    const Reprojected right = reproject(neighbour.get("albedo"), none, positions, none);
    const auto [error, covered] = trustedError(right.image, f2.get("albedo"), right.trust);
    CHECK(covered > 0.7);
    CHECK(error < 0.01);

    MotionField flipped = *field;
    for (Image* im : {&flipped.toPrevious, &flipped.toNext})
      for (float& v : im->pixels) v = -v;
    MotionField flippedNeighbour = *neighbourField;
    for (Image* im : {&flippedNeighbour.toPrevious, &flippedNeighbour.toNext})
      for (float& v : im->pixels) v = -v;
    const Image wrongPositions =
        chainPositions({{&none, &flipped}, {&none, &flippedNeighbour}}, side > 0);
    const Reprojected wrong = reproject(neighbour.get("albedo"), none, wrongPositions, none);
    CHECK(trustedError(wrong.image, f2.get("albedo"), wrong.trust).first > 5 * error);
  }
}

// A frame of a synthetic shot: a textured background (depth 10) moving by
// `shift` px per frame, and optionally a square occluder (depth 2) at `box`.
struct Synthetic {
  Image color, albedo, normal, depth;
};

float texture(double x, double y) {
  return 0.3f + 0.2f * std::sin(0.7 * x) * std::cos(0.45 * y) + 0.1f * std::sin(0.13 * (x + 2 * y));
}

Synthetic makeFrame(int w, int h, double ox, double oy, int boxX = -100, int boxY = -100,
                    int boxSize = 0) {
  Synthetic f{Image(w, h, 3), Image(w, h, 3), Image(w, h, 3), Image(w, h, 1)};
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const bool inBox = x >= boxX && x < boxX + boxSize && y >= boxY && y < boxY + boxSize;
      const float t = inBox ? 0.9f : texture(x + ox, y + oy);
      for (int c = 0; c < 3; ++c) {
        f.color.at(x, y, c) = t * (1.0f + 0.1f * c);
        f.albedo.at(x, y, c) = inBox ? 0.9f : 0.5f;
      }
      f.normal.at(x, y, 2) = inBox ? 1.0f : 0.0f;
      f.normal.at(x, y, 1) = inBox ? 0.0f : 1.0f;
      f.depth.at(x, y, 0) = inBox ? 2.0f : 10.0f;
    }
  return f;
}

MotionField constantMotion(int w, int h, float px, float py, float nx, float ny) {
  MotionField m{Image(w, h, 2), Image(w, h, 2), "synthetic", false};
  for (std::size_t i = 0; i < m.toNext.pixelCount(); ++i) {
    m.toPrevious.pixels[2 * i] = px, m.toPrevious.pixels[2 * i + 1] = py;
    m.toNext.pixels[2 * i] = nx, m.toNext.pixels[2 * i + 1] = ny;
  }
  return m;
}

Guides guides(const Synthetic& f) { return Guides{f.albedo, f.normal, f.depth}; }

}  // namespace

TEST_CASE("Blender 3.4's Vector pass: direction and sign from a render of a known camera move") {
  checkConvention("blender34");
}

TEST_CASE("Blender 5's Vector pass (one part per pass): the same convention") {
  REQUIRE(std::filesystem::exists(kMotionDir + "blender5/spp4.0002.exr"));
  checkConvention("blender5");
}

TEST_CASE("other renderers' motion names are found and decoded") {
  auto arnold = findMotionChannels({"R", "G", "B", "motionvector.R", "motionvector.G"});
  REQUIRE(arnold);
  CHECK(arnold->convention == Convention::ForwardPixels);
  auto vray =
      findMotionChannels({"R", "G", "B", "VRayVelocity.R", "VRayVelocity.G", "VRayVelocity.B"});
  REQUIRE(vray);
  CHECK(vray->channels == std::vector<std::string>{"VRayVelocity.R", "VRayVelocity.G"});
  auto prman =
      findMotionChannels({"Ci.r", "motionBack.r", "motionBack.g", "motionFore.r", "motionFore.g"});
  REQUIRE(prman);
  CHECK(prman->convention == Convention::BackFore);
  auto blender5 =
      findMotionChannels({"ViewLayer.Combined.R", "ViewLayer.Vector.W", "ViewLayer.Vector.X",
                          "ViewLayer.Vector.Y", "ViewLayer.Vector.Z"});
  REQUIRE(blender5);
  CHECK(blender5->channels.front() == "ViewLayer.Vector.X");
  CHECK_FALSE(findMotionChannels({"R", "G", "B", "Z"}));

  // Forward motion (3, 2) px, y up: the next frame shows the surface 3 px right
  // and 2 px up, i.e. (+3, -2) in rows that run down; the previous one mirrored.
  Image forward(1, 1, 2);
  forward.pixels = {3.0f, 2.0f};
  const MotionField f = decodeForward(forward);
  CHECK(f.toNext.pixels == std::vector<float>{3.0f, -2.0f});
  CHECK(f.toPrevious.pixels == std::vector<float>{-3.0f, 2.0f});
  CHECK(f.mirrored);
  Image back(1, 1, 2), fore(1, 1, 2);
  back.pixels = {-1.0f, 0.5f};
  fore.pixels = {2.0f, -1.0f};
  const MotionField bf = decodeBackFore(back, fore);
  CHECK(bf.toPrevious.pixels == std::vector<float>{-1.0f, -0.5f});
  CHECK(bf.toNext.pixels == std::vector<float>{2.0f, 1.0f});
}

TEST_CASE("motion with NaN or Inf is refused with the file's name, in either group") {
  const auto prman =
      findMotionChannels({"Ci.r", "motionBack.r", "motionBack.g", "motionFore.r", "motionFore.g"});
  REQUIRE(prman);
  Image back(2, 1, 2), fore(2, 1, 2);
  back.pixels = {-1.0f, 0.5f, 0.0f, 0.0f};
  fore.pixels = {2.0f, -1.0f, 0.0f, 0.0f};
  CHECK_NOTHROW(decodeMotion(*prman, {back, fore}, 2, 1, "shot.0001.exr"));
  fore.pixels[3] = std::numeric_limits<float>::quiet_NaN();
  CHECK_THROWS_WITH_AS(decodeMotion(*prman, {back, fore}, 2, 1, "shot.0001.exr"),
                       "shot.0001.exr: the motion holds NaN or Inf values", IoError);
  fore.pixels[3] = 0.0f, back.pixels[0] = std::numeric_limits<float>::infinity();
  CHECK_THROWS_AS(decodeMotion(*prman, {back, fore}, 2, 1, "shot.0001.exr"), IoError);
}

TEST_CASE("a separate motion file of another size is refused with the file's name") {
  const std::string middle = kMotionDir + "blender34/spp4.0002.exr";
  CHECK_THROWS_WITH_AS(readMotion(middle, 32, 32), doctest::Contains("spp4.0002.exr"), IoError);
  CHECK_FALSE(
      readMotion(std::string(DN_TESTDATA) + "/renderers/blender5_hdri_4spp.exr", 1, 1).has_value());
}

TEST_CASE("reprojection with a known sub-pixel shift recovers the current frame") {
  const int w = 48, h = 32;
  // The scene slides: frame t shows texture at x + 2.5 t, y - 1 t.
  const Synthetic current = makeFrame(w, h, 0.0, 0.0), previous = makeFrame(w, h, -2.5, 1.0);
  // The surface at pixel x of this frame was at x + 2.5 (and y - 1) before.
  const MotionField mc = constantMotion(w, h, 2.5f, -1.0f, -2.5f, 1.0f);
  const MotionField mp = constantMotion(w, h, 2.5f, -1.0f, -2.5f, 1.0f);
  const Guides gc = guides(current), gp = guides(previous);
  const Image positions = chainPositions({{&gc, &mc}, {&gp, &mp}}, false);
  const Reprojected r = reproject(previous.color, gp, positions, gc);
  double maxError = 0.0;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const bool inside = x + 2.5 <= w - 1 && y - 1 >= 0;
      if (!inside) {
        if (x + 2.5 > w - 0.5) CHECK(r.trust.at(x, y, 0) == 0.0f);  // left the screen
        continue;
      }
      REQUIRE(r.trust.at(x, y, 0) > 0.99f);
      for (int c = 0; c < 3; ++c)
        maxError =
            std::max(maxError, double(std::abs(r.image.at(x, y, c) - current.color.at(x, y, c))));
    }
  CHECK(maxError < 0.02);  // bilinear interpolation of a smooth texture
}

TEST_CASE("disoccluded pixels behind a moving occluder are rejected, the rest kept") {
  const int w = 40, h = 24, size = 8;
  // The background is still; a box moves 4 px right per frame: at x = 10 in the
  // previous frame, x = 14 now. Pixels 10..13 were behind it and are uncovered now.
  const Synthetic previous = makeFrame(w, h, 0, 0, 10, 8, size);
  const Synthetic current = makeFrame(w, h, 0, 0, 14, 8, size);
  auto motionOf = [&](int boxX) {
    MotionField m = constantMotion(w, h, 0, 0, 0, 0);
    for (int y = 8; y < 8 + size; ++y)
      for (int x = boxX; x < boxX + size; ++x) {
        m.toPrevious.at(x, y, 0) = -4.0f;
        m.toNext.at(x, y, 0) = 4.0f;
      }
    return m;
  };
  const MotionField mc = motionOf(14), mp = motionOf(10);
  const Guides gc = guides(current), gp = guides(previous);
  const Image positions = chainPositions({{&gc, &mc}, {&gp, &mp}}, false);
  const Reprojected r = reproject(previous.color, gp, positions, gc);
  for (int y = 8; y < 8 + size; ++y) {
    for (int x = 10; x < 14; ++x) CHECK(r.trust.at(x, y, 0) == 0.0f);  // was behind the box
    for (int x = 14; x < 22; ++x) CHECK(r.trust.at(x, y, 0) == 1.0f);  // the box itself
  }
  CHECK(r.trust.at(2, 2, 0) == 1.0f);
  CHECK(r.trust.at(30, 20, 0) == 1.0f);
  // Without motion back (the round trip) the guides alone still reject them,
  // but for the column next to the box's edge, whose neighbourhood shows the
  // box: the previous frame shows the box (depth 2) where the background (10) is now.
  TrustOptions noRoundTrip;
  noRoundTrip.roundTripPixels = 1e9;
  const Reprojected r2 =
      reproject(previous.color, gp, chainPositions({{&gc, &mc}, {&gp, &mc}}, false, noRoundTrip),
                gc, noRoundTrip);
  for (int x = 10; x < 13; ++x) CHECK(r2.trust.at(x, 10, 0) == 0.0f);
  CHECK(r2.trust.at(13, 10, 0) == 1.0f);
  noRoundTrip.neighbourhood = 0;
  const Reprojected r3 =
      reproject(previous.color, gp, chainPositions({{&gc, &mc}, {&gp, &mc}}, false, noRoundTrip),
                gc, noRoundTrip);
  for (int x = 10; x < 14; ++x) CHECK(r3.trust.at(x, 10, 0) == 0.0f);
}

TEST_CASE("an anti-aliased edge whose coverage changed between frames is still trusted") {
  // Still frames of a box; at its left edge (x = 14) the previous frame's few
  // samples all missed the box, and now 60% of them hit it.
  const int w = 40, h = 24;
  Synthetic previous = makeFrame(w, h, 0, 0, 14, 8, 8), current = previous;
  auto blendEdge = [](Synthetic& f, float box) {
    for (int y = 8; y < 16; ++y) {
      f.depth.at(14, y, 0) = box * 2.0f + (1.0f - box) * 10.0f;
      for (int c = 0; c < 3; ++c) f.albedo.at(14, y, c) = box * 0.9f + (1.0f - box) * 0.5f;
      f.normal.at(14, y, 1) = 1.0f - box, f.normal.at(14, y, 2) = box;
    }
  };
  blendEdge(previous, 0.0f);
  blendEdge(current, 0.6f);
  const MotionField still = constantMotion(w, h, 0, 0, 0, 0);
  const Guides gc = guides(current), gp = guides(previous);
  const Image positions = chainPositions({{&gc, &still}, {&gp, &still}}, false);
  CHECK(reproject(previous.color, gp, positions, gc).trust.at(14, 10, 0) == 1.0f);
  TrustOptions exact;
  exact.neighbourhood = 0;
  CHECK(reproject(previous.color, gp, positions, gc, exact).trust.at(14, 10, 0) == 0.0f);
}

TEST_CASE("cubic resampling keeps a texture's edges sharper than bilinear, never across surfaces") {
  // A sharp stripe texture on one surface, brought in from half a pixel away.
  const int w = 48, h = 16;
  auto stripes = [&](float shift) {
    Image im(w, h, 3);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        const double u = x + shift;  // a smooth-edged square wave, period 8 px
        const float v = static_cast<float>(0.5 + 0.4 * std::tanh(3.0 * std::sin(u * M_PI / 4)));
        for (int c = 0; c < 3; ++c) im.at(x, y, c) = v;
      }
    return im;
  };
  const Image current = stripes(0.0), previous = stripes(-0.5);
  const Synthetic flat = makeFrame(w, h, 0, 0);
  Guides g = guides(flat);
  g.albedo = Image();  // the stripes are a texture: the albedo test would see them
  const MotionField mc = constantMotion(w, h, 0.5f, 0, -0.5f, 0);
  const Image positions = chainPositions({{&g, &mc}, {&g, &mc}}, false);
  TrustOptions bilinearOnly;
  bilinearOnly.cubic = false;
  const Reprojected cubic = reproject(previous, g, positions, g);
  const Reprojected bilinear = reproject(previous, g, positions, g, bilinearOnly);
  double cubicError = 0.0, bilinearError = 0.0;
  for (int y = 2; y < h - 2; ++y)
    for (int x = 2; x < w - 3; ++x) {
      cubicError += std::abs(cubic.image.at(x, y, 0) - current.at(x, y, 0));
      bilinearError += std::abs(bilinear.image.at(x, y, 0) - current.at(x, y, 0));
    }
  CHECK(cubicError < 0.75 * bilinearError);

  // Where a cubic tap shows a surface not seen around the destination (x = 22:
  // its taps reach x = 24, beyond a depth edge), bilinear is kept.
  Guides split = g;
  for (int y = 0; y < h; ++y)
    for (int x = 24; x < w; ++x) split.depth.at(x, y, 0) = 2.0f;
  const Reprojected edge = reproject(previous, split, positions, split);
  const Reprojected edgeBilinear = reproject(previous, split, positions, split, bilinearOnly);
  CHECK(edge.image.at(22, 8, 0) == edgeBilinear.image.at(22, 8, 0));
  CHECK(edge.image.at(21, 8, 0) != edgeBilinear.image.at(21, 8, 0));
}

TEST_CASE("images resampled together are their channels stacked, bit for bit") {
  // A smooth image and a step from black: Catmull-Rom overshoots below 0 on
  // the step's dark side, and there both images fall back to bilinear.
  const int w = 32, h = 12;
  Image smooth(w, h, 3), step(w, h, 2), stacked(w, h, 5);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      for (int c = 0; c < 3; ++c) smooth.at(x, y, c) = 1.0f + 0.3f * std::sin(0.4f * x + c + y);
      for (int c = 0; c < 2; ++c) step.at(x, y, c) = x < w / 2 ? 0.0f : 1.0f + c;
      for (int c = 0; c < 5; ++c)
        stacked.at(x, y, c) = c < 3 ? smooth.at(x, y, c) : step.at(x, y, c - 3);
    }
  Image positions(w, h, 2);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) positions.at(x, y, 0) = x + 0.5f, positions.at(x, y, 1) = y + 0.25f;
  const Guides g = guides(makeFrame(w, h, 0, 0));
  const Resampling plan = planResampling(g, positions, g);
  const std::vector<Image> together = resample(plan, {&smooth, &step});
  const Image reference = resample(plan, stacked);
  REQUIRE(together.size() == 2);
  for (std::size_t i = 0; i < reference.pixelCount(); ++i)
    for (int c = 0; c < 5; ++c) {
      const float value = c < 3 ? together[0].pixels[3 * i + c] : together[1].pixels[2 * i + c - 3];
      CHECK(std::memcmp(&value, &reference.pixels[5 * i + c], sizeof value) == 0);
    }
  // Left of the step the smooth image alone keeps Catmull-Rom; together it does not.
  const int x = w / 2 - 2, y = h / 2;
  CHECK(resample(plan, smooth).at(x, y, 0) != together[0].at(x, y, 0));
  CHECK(resample(plan, smooth).at(2, y, 0) == together[0].at(2, y, 0));
}

TEST_CASE("colour images resampled alone or in pairs are as the general path, bit for bit") {
  // A smooth image and one stepping up from black, where Catmull-Rom
  // overshoots below 0 and both fall back to bilinear; a channel of ones
  // sends the same images down the general path without changing that choice.
  const int w = 32, h = 12;
  Image smooth(w, h, 3), dark(w, h, 3), ones(w, h, 1, 1.0f), stacked(w, h, 6), darkAndOne(w, h, 4);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < 3; ++c) {
        smooth.at(x, y, c) = 1.0f + 0.3f * std::sin(0.4f * x + c + y);
        dark.at(x, y, c) = x < w / 2 ? 0.0f : 1.0f + c + 0.1f * y;
        stacked.at(x, y, c) = smooth.at(x, y, c), stacked.at(x, y, 3 + c) = dark.at(x, y, c);
        darkAndOne.at(x, y, c) = dark.at(x, y, c);
      }
  Image positions(w, h, 2);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) positions.at(x, y, 0) = x + 0.3f, positions.at(x, y, 1) = y + 0.6f;
  const Guides g = guides(makeFrame(w, h, 0, 0));
  const Resampling plan = planResampling(g, positions, g);
  auto sameBits = [](const Image& a, const Image& b, int channels, int first) {
    for (std::size_t i = 0; i < a.pixelCount(); ++i)
      for (int c = 0; c < a.channels; ++c)
        if (std::memcmp(&a.pixels[i * a.channels + c], &b.pixels[i * channels + first + c],
                        sizeof(float)) != 0)
          return false;
    return true;
  };
  const std::vector<Image> pair = resample(plan, {&smooth, &dark});
  const Image general = resample(plan, stacked);
  CHECK(sameBits(pair[0], general, 6, 0));
  CHECK(sameBits(pair[1], general, 6, 3));
  const Image alone = resample(plan, dark);
  CHECK(sameBits(alone, resample(plan, {&dark, &ones})[0], 3, 0));
  CHECK(sameBits(alone, resample(plan, darkAndOne), 4, 0));
  // Beside the step Catmull-Rom would go below 0; bilinear gives the black.
  CHECK(alone.at(w / 2 - 2, h / 2, 0) == 0.0f);
}

TEST_CASE("nearest-pixel reprojection rounds halves away from zero and clamps to the frame") {
  const int w = 7, h = 5;
  Image source(w, h, 1);
  for (std::size_t i = 0; i < source.pixels.size(); ++i) source.pixels[i] = static_cast<float>(i);
  const float below = std::nextafter(0.5f, 0.0f), above = std::nextafter(0.5f, 1.0f);
  const std::vector<float> xs = {-3.0f, -0.5f, -below, 0.0f,     below,     0.5f,  above,
                                 2.5f,  3.5f,  5.49f,  w - 0.5f, w - below, 40.0f, 1e30f};
  Image positions(static_cast<int>(xs.size()), 1, 2);
  for (std::size_t i = 0; i < xs.size(); ++i) {
    positions.pixels[2 * i] = xs[i];
    positions.pixels[2 * i + 1] = xs[i] / 2;
  }
  const Image moved = reprojectNearest(source, positions);
  for (std::size_t i = 0; i < xs.size(); ++i) {
    auto index = [](float v, int size) {  // the reference: std::lround, clamped
      const double r = std::abs(v) > 1e9f ? (v > 0 ? 1e9 : -1e9) : double(std::lround(v));
      return static_cast<int>(std::clamp(r, 0.0, double(size - 1)));
    };
    CAPTURE(xs[i]);
    CHECK(moved.pixels[i] == source.at(index(xs[i], w), index(xs[i] / 2, h), 0));
    CHECK(nearestPixels(positions, w, h)[i] == static_cast<std::int32_t>(moved.pixels[i]));
  }
  // A lost pixel has no source (reprojectNearest writes 0 there).
  positions.pixels[2] = std::numeric_limits<float>::quiet_NaN();
  CHECK(nearestPixels(positions, w, h)[1] == -1);
  CHECK(reprojectNearest(source, positions).pixels[1] == 0.0f);
}

namespace {

// A still shot's frame: truth plus noise (seeded), "denoised" as truth plus a
// smaller leftover error that changes with the seed, as a network's does (at
// 4-16 spp, the differences of Cycles frames denoised alone are 0.16-0.37 of
// the render's noise; here 0.15 x sqrt(2) = 0.21).
temporal::WindowFrame stillFrame(const Synthetic& truth, unsigned noiseSeed,
                                 unsigned leftoverSeed) {
  std::mt19937 noise(noiseSeed), leftover(leftoverSeed);
  std::normal_distribution<float> big(0.0f, 0.1f), small(0.0f, 0.015f);
  temporal::WindowFrame f;
  f.noisy = truth.color;
  f.denoised = truth.color;
  for (std::size_t i = 0; i < f.noisy.floats().pixels.size(); ++i) {
    f.noisy.floats().pixels[i] += big(noise);
    f.denoised.floats().pixels[i] += small(leftover);
  }
  f.guides = guides(truth);
  f.motion = constantMotion(truth.color.width, truth.color.height, 0, 0, 0, 0);
  return f;
}

// `count` frames of a still shot, their seeds counting up from the two given.
std::vector<temporal::WindowFrame> stillShot(const Synthetic& truth, unsigned count,
                                             unsigned noiseSeed, unsigned leftoverSeed) {
  std::vector<temporal::WindowFrame> frames;
  for (unsigned t = 0; t < count; ++t)
    frames.push_back(stillFrame(truth, noiseSeed + t, leftoverSeed + t));
  return frames;
}

// Three frames of a still shot whose neighbours (frames 0 and 2) are lit 20%
// brighter everywhere: a lamp moved, too faint a change for the per-pixel
// tests at this noise, too wide to be a shadow.
std::vector<temporal::WindowFrame> brighterNeighbours(const Synthetic& truth, unsigned noiseSeed,
                                                      unsigned leftoverSeed) {
  std::vector<temporal::WindowFrame> frames = stillShot(truth, 3, noiseSeed, leftoverSeed);
  for (unsigned t : {0u, 2u}) {
    for (float& v : frames[t].denoised.floats().pixels) v *= 1.2f;
    for (float& v : frames[t].noisy.floats().pixels) v *= 1.2f;
  }
  return frames;
}

// Three frames of a pan, a pixel a frame, their seeds counting up from the two given.
std::vector<temporal::WindowFrame> panShot(unsigned noiseSeed, unsigned leftoverSeed) {
  std::vector<temporal::WindowFrame> frames;
  for (int t = 0; t < 3; ++t) {
    frames.push_back(stillFrame(makeFrame(32, 24, t, 0), noiseSeed + t, leftoverSeed + t));
    frames.back().motion = constantMotion(32, 24, 1, 0, -1, 0);
  }
  return frames;
}

// The window over every frame given.
std::vector<const temporal::WindowFrame*> windowOf(
    const std::vector<temporal::WindowFrame>& frames) {
  std::vector<const temporal::WindowFrame*> window;
  for (const auto& f : frames) window.push_back(&f);
  return window;
}

std::vector<const Image*> pointersTo(const std::vector<Image>& images) {
  std::vector<const Image*> out;
  for (const Image& image : images) out.push_back(&image);
  return out;
}

double meanSquaredError(const Image& a, const Image& b) {
  double s = 0.0;
  for (std::size_t i = 0; i < a.pixels.size(); ++i) s += std::pow(a.pixels[i] - b.pixels[i], 2);
  return s / a.pixels.size();
}

}  // namespace

TEST_CASE("chain positions along a chain equal each prefix's, bit for bit") {
  // Four frames moving 2 px a frame, each vector off by up to 0.4 px: some
  // pixels leave the screen or fail a round trip along the chain, most not.
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> error(-0.4f, 0.4f);
  std::vector<MotionField> fields(4);
  for (MotionField& f : fields) {
    f.toPrevious = f.toNext = Image(64, 48, 2);
    for (float& v : f.toPrevious.pixels) v = 2.0f + error(rng);
    for (float& v : f.toNext.pixels) v = -2.0f + error(rng);
  }
  const Guides none;
  for (bool forward : {false, true}) {
    std::vector<FrameGeometry> chain;
    for (const MotionField& f : fields) chain.push_back({&none, &f});
    const std::vector<Image> along = chainPositionsAlong(chain, forward);
    REQUIRE(along.size() == 3);
    for (std::size_t k = 0; k < along.size(); ++k) {
      const std::vector<FrameGeometry> prefix(chain.begin(), chain.begin() + k + 2);
      const Image alone = chainPositions(prefix, forward);
      CHECK(std::memcmp(along[k].pixels.data(), alone.pixels.data(),
                        alone.pixels.size() * sizeof(float)) == 0);
    }
    // Made in bands of rows (as threads share them out), the same bits.
    std::vector<Image> banded(3, Image(64, 48, 2, -1.0f));
    const int rows[] = {0, 17, 30, 48};
    for (int b = 0; b < 3; ++b)
      chainPositionsRows(chain, forward, {}, rows[b], rows[b + 1], banded);
    CHECK_THROWS_AS(chainPositionsRows(chain, forward, {}, 40, 49, banded), std::invalid_argument);
    for (std::size_t k = 0; k < along.size(); ++k)
      CHECK(std::memcmp(along[k].pixels.data(), banded[k].pixels.data(),
                        along[k].pixels.size() * sizeof(float)) == 0);
    const auto lost = std::count_if(along.back().pixels.begin(), along.back().pixels.end(),
                                    [](float v) { return std::isnan(v); });
    CHECK(lost > 0);
    CHECK(lost < static_cast<long>(along.back().pixels.size() / 2));
  }
}

TEST_CASE("temporal filter: independent leftovers average down; repeated noise does no harm") {
  const Synthetic truth = makeFrame(32, 24, 0, 0);
  std::vector<temporal::WindowFrame> frames = stillShot(truth, 5, 100, 200);
  const std::vector<const temporal::WindowFrame*> window = windowOf(frames);
  const temporal::TemporalResult r = temporal::filterFrame(window, 2);
  CHECK(r.stats.neighbours == 4);
  CHECK(r.stats.repeatedNoise == 0);
  CHECK(r.stats.historyShare > 0.6);
  CHECK(meanSquaredError(r.color, truth.color) <
        0.4 * meanSquaredError(frames[2].denoised.floats(), truth.color));

  // A fixed seed on a still camera: every frame the same noise and the same result.
  std::vector<temporal::WindowFrame> repeated(5, stillFrame(truth, 7, 8));
  const temporal::TemporalResult same = temporal::filterFrame(windowOf(repeated), 2);
  CHECK(same.stats.repeatedNoise == 4);
  CHECK(same.stats.historyShare == 0.0);
  CHECK(same.color.pixels == repeated[2].denoised.floats().pixels);

  // One-sided at the end of a shot, and a missing frame ends the chain.
  std::vector<const temporal::WindowFrame*> edge = {&frames[0], &frames[1], nullptr, &frames[3]};
  CHECK(temporal::filterFrame(edge, 0).stats.neighbours == 1);
  CHECK(temporal::filterFrame(edge, 3).stats.neighbours == 0);
}

TEST_CASE("temporal filter: the noisy renders accumulate with its weights, variance over frames") {
  const Synthetic truth = makeFrame(32, 24, 0, 0);
  std::vector<temporal::WindowFrame> frames = stillShot(truth, 5, 500, 600);
  const temporal::TemporalResult r = temporal::filterFrame(windowOf(frames), 2);
  REQUIRE(r.history.sameShape(truth.color));
  // Every neighbour trusted nearly everywhere: close to 5 frames a pixel.
  CHECK(r.stats.accumulatedFrames > 4.0);
  CHECK(r.stats.accumulatedFrames <= 5.0);
  // The render's noise variance (0.1^2) falls by the effective frame count.
  const std::vector<float>& counts = r.historyFrames.pixels;
  CHECK(*std::min_element(counts.begin(), counts.end()) >= 1.0f);
  double expected = 0.0;
  for (float n : counts) expected += 0.01 / n / counts.size();
  const double measured = meanSquaredError(r.history, truth.color);
  CHECK(measured > 0.8 * expected);
  CHECK(measured < 1.25 * expected);

  // Repeated noise adds no sample: the history is the frame's render itself.
  std::vector<temporal::WindowFrame> repeated(5, stillFrame(truth, 7, 8));
  const temporal::TemporalResult same = temporal::filterFrame(windowOf(repeated), 2);
  CHECK(same.stats.accumulatedFrames == 1.0);
  CHECK(same.history.pixels == repeated[2].noisy.floats().pixels);
}

TEST_CASE("temporal filter: the two estimates blend by the accumulated share") {
  Image filtered(2, 1, 3, 1.0f), accumulated(2, 1, 3, 3.0f);
  accumulated.at(1, 0, 2) = 5.0f;
  const Image half = temporal::blendWithHistory(filtered, accumulated, 0.5);
  CHECK(half.at(0, 0, 0) == 2.0f);
  CHECK(half.at(1, 0, 2) == 3.0f);
  CHECK(temporal::blendWithHistory(filtered, accumulated, 0.0).pixels == filtered.pixels);
  CHECK_THROWS_AS(temporal::blendWithHistory(filtered, Image(1, 1, 3), 0.5), std::invalid_argument);

  // A share per pixel: all of the filtered in one, all of the history in the other.
  Image share(2, 1, 1, 0.0f);
  share.at(1, 0, 0) = 1.0f;
  const Image perPixel = temporal::blendWithHistory(filtered, accumulated, share);
  CHECK(perPixel.at(0, 0, 1) == 1.0f);
  CHECK(perPixel.at(1, 0, 2) == 5.0f);
  CHECK_THROWS_AS(temporal::blendWithHistory(filtered, accumulated, Image(2, 1, 3)),
                  std::invalid_argument);
}

TEST_CASE("a light pass's history share follows the frames its render gathered") {
  temporal::TemporalOptions options;
  options.accumulatedShare = 0.35;
  Image frames(4, 1, 1);
  frames.pixels = {1.0f, 1.5f, 2.0f, 7.0f};
  const Image share = temporal::passHistoryShare(frames, 0.2, options);
  CHECK(share.pixels[0] == doctest::Approx(0.2));
  CHECK(share.pixels[1] == doctest::Approx(0.275));
  CHECK(share.pixels[2] == doctest::Approx(0.35));
  CHECK(share.pixels[3] == doctest::Approx(0.35));
  // None where nothing was gathered; never above the colour's share.
  CHECK(temporal::passHistoryShare(frames, 0.0, options).pixels[0] == 0.0f);
  CHECK(temporal::passHistoryShare(frames, 0.0, options).pixels[1] == doctest::Approx(0.175));
  CHECK(temporal::passHistoryShare(frames, 0.9, options).pixels[0] == doctest::Approx(0.35));
}

TEST_CASE("a view-dependent pass's share alone follows how much of the light is view-dependent") {
  temporal::TemporalOptions options;
  options.accumulatedShare = 0.35;
  options.viewDependentShareAlone = 0.2;
  options.viewDependentShareFull = 0.5;
  Image viewDependent(4, 1, 1);
  viewDependent.pixels = {0.0f, 0.25f, 0.5f, 1.0f};
  const Image alone = temporal::viewDependentAlone(viewDependent, options);
  CHECK(alone.pixels[0] == 0.0f);  // matte: the pass alone
  CHECK(alone.pixels[1] == doctest::Approx(0.1));
  CHECK(alone.pixels[2] == doctest::Approx(0.2));
  CHECK(alone.pixels[3] == doctest::Approx(0.2));
  // Where the render gathered two frames the share is the colour's, whatever the light.
  Image frames(4, 1, 1, 1.0f);
  frames.pixels[1] = 2.0f;
  const Image share = temporal::passHistoryShare(frames, alone, options);
  CHECK(share.pixels[0] == 0.0f);
  CHECK(share.pixels[1] == doctest::Approx(0.35));
  CHECK(share.pixels[3] == doctest::Approx(0.2));
  options.viewDependentShareFull = 0.0;  // off: in full everywhere
  CHECK(temporal::viewDependentAlone(viewDependent, options).pixels[0] == doctest::Approx(0.2));
  CHECK_THROWS_AS(temporal::passHistoryShare(frames, Image(3, 1, 1), options),
                  std::invalid_argument);
}

TEST_CASE("temporal filter: the past frames' denoised histories average with the frame's own") {
  const Synthetic truth = makeFrame(32, 24, 0, 0);
  std::vector<temporal::WindowFrame> frames = stillShot(truth, 5, 700, 800);
  // Each history: the truth plus a leftover error of its own.
  for (unsigned t = 0; t < frames.size(); ++t)
    frames[t].history = stillFrame(truth, 0, 900 + t).denoised;
  const Image own = frames[2].history.floats();

  // Only the past counts: the future's histories are not there yet in a run.
  std::vector<temporal::WindowFrame> futureOnly = frames;
  futureOnly[0].history = futureOnly[1].history = Image();
  const temporal::TemporalResult ahead = temporal::filterFrame(windowOf(futureOnly), 2);
  CHECK(ahead.pastHistories.empty());
  CHECK(temporal::historyMean(own, ahead).pixels == own.pixels);

  const temporal::TemporalResult r = temporal::filterFrame(windowOf(frames), 2);
  REQUIRE(r.pastHistories.images.size() == 2);
  for (const std::vector<double>& weight : r.pastHistories.weights) {
    CHECK(*std::max_element(weight.begin(), weight.end()) <= 1.0);
    // Trusted nearly everywhere: nothing moved.
    CHECK(std::count(weight.begin(), weight.end(), 0.0) < 0.1 * weight.size());
  }
  // Three independent leftovers: the error's variance falls to about a third.
  const Image mean = temporal::historyMean(own, r);
  CHECK(meanSquaredError(mean, truth.color) < 0.45 * meanSquaredError(own, truth.color));
  CHECK_THROWS_AS(temporal::historyMean(Image(1, 1, 3), r), std::invalid_argument);

  // A light that moved since: the past histories are brighter on the left,
  // which their results were not. There the frame keeps its own history.
  std::vector<temporal::WindowFrame> relit = frames;
  for (unsigned t : {0u, 1u})
    for (int y = 0; y < 24; ++y)
      for (int x = 0; x < 12; ++x)
        for (int c = 0; c < 3; ++c) relit[t].history.floats().at(x, y, c) += 0.6f;
  const Image kept = temporal::historyMean(own, temporal::filterFrame(windowOf(relit), 2));
  double brighter = 0.0;
  for (int y = 0; y < 24; ++y)
    for (int x = 0; x < 12; ++x) brighter += (kept.at(x, y, 1) - own.at(x, y, 1)) / (24 * 12);
  CHECK(std::abs(brighter) < 0.02);  // a blind average: 0.4
}

TEST_CASE("temporal filter: a past history counts only where the surface stood still") {
  // The camera pans 1 px a frame: every history was resampled on its way in.
  std::vector<temporal::WindowFrame> frames;
  for (int t = 0; t < 3; ++t) {
    const Synthetic truth = makeFrame(32, 24, t, 0);
    frames.push_back(stillFrame(truth, 40 + t, 50 + t));
    frames.back().motion = constantMotion(32, 24, 1, 0, -1, 0);
    frames.back().history = frames.back().denoised;
  }
  const temporal::TemporalResult r = temporal::filterFrame(windowOf(frames), 1);
  CHECK(r.stats.historyShare > 0.3);  // the results are averaged
  CHECK(r.pastHistories.empty());     // the histories are not
}

TEST_CASE("temporal filter: a visible sun does not hide the rest of the frame") {
  const Synthetic truth = makeFrame(128, 96, 0, 0);
  std::vector<temporal::WindowFrame> frames = stillShot(truth, 5, 1200, 1300);
  // A 4 x 4 sun 10^6 times brighter than the room, which the denoiser dims at
  // its edge the same way in every frame: most of each frame's mean, and of
  // its noisy-minus-denoised residual, until the tests' exposure ignores it.
  for (auto& f : frames)
    for (int y = 10; y < 14; ++y)
      for (int x = 100; x < 104; ++x)
        for (int c = 0; c < 3; ++c) {
          f.noisy.floats().at(x, y, c) = 1e6f;
          f.denoised.floats().at(x, y, c) = 1e5f;
        }
  const temporal::TemporalResult r = temporal::filterFrame(windowOf(frames), 2);
  CHECK(r.stats.repeatedNoise == 0);
  CHECK(r.stats.historyShare > 0.6);
}

TEST_CASE("temporal filter: a moving shadow in a neighbour is not averaged in") {
  const Synthetic truth = makeFrame(32, 24, 0, 0);
  std::vector<temporal::WindowFrame> frames = stillShot(truth, 3, 300, 400);
  // The next frame has a shadow (a quarter of the light) over x < 12.
  for (int y = 0; y < 24; ++y)
    for (int x = 0; x < 12; ++x)
      for (int c = 0; c < 3; ++c) {
        frames[2].denoised.floats().at(x, y, c) *= 0.25f;
        frames[2].noisy.floats().at(x, y, c) *= 0.25f;
      }
  const std::vector<const temporal::WindowFrame*> window = windowOf(frames);
  const temporal::TemporalResult r = temporal::filterFrame(window, 1);
  // Inside the shadow's region the result stays near the current frame's light,
  // at most a few percent darker, not the 3/8 darker a blind average would give.
  // So does the accumulated render.
  double result = 0.0, history = 0.0, light = 0.0;
  for (int y = 0; y < 24; ++y)
    for (int x = 0; x < 12; ++x) {
      result += r.color.at(x, y, 1), history += r.history.at(x, y, 1);
      light += truth.color.at(x, y, 1);
    }
  CHECK(result / light > 0.95);
  CHECK(history / light > 0.95);
}

TEST_CASE("temporal filter: a blotch in the frame's own result is averaged out, not kept") {
  const Synthetic truth = makeFrame(32, 24, 0, 0);
  std::vector<temporal::WindowFrame> frames = stillShot(truth, 9, 1000, 1100);
  // The frame's leftover error has a blotch: 6 x 6 pixels 0.5 too bright, which
  // its neighbours do not share.
  for (int y = 8; y < 14; ++y)
    for (int x = 8; x < 14; ++x)
      for (int c = 0; c < 3; ++c) frames[4].denoised.floats().at(x, y, c) += 0.5f;
  auto blotchError = [&](double reference) {
    temporal::TemporalOptions options;
    options.colourReference = reference;
    // The drift's box covers this small frame whole, where the blotch is a
    // change of the frame's light (5 %): at 1080p a blotch is a speck in it.
    options.driftThreshold = 0.0;
    const temporal::TemporalResult r = temporal::filterFrame(windowOf(frames), 4, options);
    double e = 0.0;
    for (int y = 8; y < 14; ++y)
      for (int x = 8; x < 14; ++x) e += r.color.at(x, y, 1) - truth.color.at(x, y, 1);
    return e / 36.0;
  };
  // Tested against the frame alone, every neighbour differs there and is left
  // out; tested against the window's mean, they are kept and the blotch fades.
  CHECK(blotchError(0.0) > 0.25);
  CHECK(blotchError(0.75) < 0.07);  // 0.5 / 9 if all nine frames were averaged
}

TEST_CASE("temporal filter: a neighbour whose light changed over the frame is relit first") {
  const Synthetic truth = makeFrame(32, 24, 0, 0);
  const std::vector<temporal::WindowFrame> frames = brighterNeighbours(truth, 500, 600);
  const temporal::TemporalResult r = temporal::filterFrame(windowOf(frames), 1);
  CHECK(r.stats.relit == 2);
  CHECK(r.stats.changedLight == 0);
  CHECK(r.stats.historyShare > 0.5);
  // Brought to the frame's light, they lower its leftover error, and do not
  // brighten it.
  CHECK(meanSquaredError(r.color, truth.color) <
        0.9 * meanSquaredError(frames[1].denoised.floats(), truth.color));
  double result = 0.0, light = 0.0;
  for (std::size_t i = 1; i < r.color.pixels.size(); i += 3)
    result += r.color.pixels[i], light += truth.color.pixels[i];
  CHECK(result / light == doctest::Approx(1.0).epsilon(0.01));
  // Their renders are accumulated at the frame's light too, with their samples.
  CHECK(r.stats.accumulatedFrames > 2.0);
  double history = 0.0;
  for (std::size_t i = 1; i < r.history.pixels.size(); i += 3) history += r.history.pixels[i];
  CHECK(history / light == doctest::Approx(1.0).epsilon(0.01));
}

TEST_CASE("temporal filter: shadows sweeping the whole frame a little each frame are relit") {
  // The sun moving: soft shadows cross the frame a few pixels a frame, each
  // pixel's change too faint for the per-pixel tests at 4 spp's noise.
  auto sunlit = [](int t) {
    Synthetic f = makeFrame(64, 48, 0, 0);
    for (int y = 0; y < 48; ++y)
      for (int x = 0; x < 64; ++x) {
        const double shade = 0.85 + 0.15 * std::sin(2.0 * M_PI * (x + 0.5 * y - 5.0 * t) / 80.0);
        for (int c = 0; c < 3; ++c) f.color.at(x, y, c) *= static_cast<float>(shade);
      }
    return f;
  };
  std::vector<temporal::WindowFrame> frames;
  for (int t = 0; t < 5; ++t) frames.push_back(stillFrame(sunlit(t), 700 + t, 800 + t));
  const Image truth = sunlit(2).color;
  temporal::TemporalOptions spreadAlone;
  spreadAlone.changedLightMean = 1e9;
  const temporal::TemporalResult filtered = temporal::filterFrame(windowOf(frames), 2, spreadAlone);
  const temporal::TemporalResult r = temporal::filterFrame(windowOf(frames), 2);
  // Their spread is too low to be a change of light; averaged over the frame,
  // the renders' light test finds it in the neighbours two frames away.
  CHECK(filtered.stats.relit == 0);
  CHECK(r.stats.relit == 2);
  for (const temporal::NeighbourWeights& n : r.weights.neighbours)
    CHECK(n.relit == (n.frame == 0 || n.frame == 4));
  CHECK(meanSquaredError(r.color, truth) < 0.7 * meanSquaredError(filtered.color, truth));
}

namespace {

// Five frames of a still shot whose top half a light drifts over, `step`
// dimmer a frame before the last (a lamp's pool edging away across a
// wall): frame to frame, too faint for the per-pixel tests at this noise.
std::vector<temporal::WindowFrame> driftingShot(const Synthetic& truth, float step) {
  std::vector<temporal::WindowFrame> frames = stillShot(truth, 5, 910, 1010);
  for (int t = 0; t < 5; ++t) {
    const float light = 1.0f + step * static_cast<float>(t - 4);
    temporal::WindowFrame& f = frames[static_cast<std::size_t>(t)];
    for (int y = 0; y < f.denoised.height() / 2; ++y)
      for (int x = 0; x < f.denoised.width(); ++x)
        for (int c = 0; c < 3; ++c)
          f.denoised.floats().at(x, y, c) *= light, f.noisy.floats().at(x, y, c) *= light;
  }
  return frames;
}

// The mean of channel 1 of `image` over its top half, relative to `truth`'s.
double topLight(const Image& image, const Image& truth) {
  double a = 0.0, b = 0.0;
  for (int y = 0; y < image.height / 2; ++y)
    for (int x = 0; x < image.width; ++x) a += image.at(x, y, 1), b += truth.at(x, y, 1);
  return a / b;
}

}  // namespace

TEST_CASE("temporal filter: a light drifting over part of the frame is brought to its light") {
  const Synthetic truth = makeFrame(96, 64, 0, 0);
  const std::vector<temporal::WindowFrame> frames = driftingShot(truth, 0.03f);
  temporal::TemporalOptions off, on;
  off.driftThreshold = 0.0;
  off.driftBox = on.driftBox = 7;
  off.radius = on.radius = 2;  // the two past frames: 3 % and 6 % dimmer at the top
  const temporal::TemporalResult kept = temporal::filterFrame(windowOf(frames), 4, off);
  const temporal::TemporalResult r = temporal::filterFrame(windowOf(frames), 4, on);
  // Both pass the tests as they are, and darken the top.
  CHECK(kept.stats.relit == 0);
  CHECK(kept.stats.changedLight == 0);
  CHECK(kept.stats.historyShare > 0.5);
  const double darkened = 1.0 - topLight(kept.color, truth.color);
  CHECK(darkened > 0.015);
  // The one more than 5 % off is brought to the frame's light where it
  // drifted: the top darkens far less, the bottom is as before.
  CHECK(r.stats.drifted == 1);
  CHECK(r.stats.relit == 0);
  CHECK(1.0 - topLight(r.color, truth.color) < 0.5 * darkened);
  for (int x = 0; x < 96; ++x) CHECK(r.color.at(x, 60, 1) == kept.color.at(x, 60, 1));
  CHECK(meanSquaredError(r.color, truth.color) < 0.8 * meanSquaredError(kept.color, truth.color));
  CHECK(r.stats.historyShare == kept.stats.historyShare);
  // Another image of the frames (a light pass) is brought to it alike, by its
  // own ratio; the results themselves give the colour bit for bit.
  std::vector<const Image*> results;
  for (const auto& f : frames) results.push_back(&f.denoised.floats());
  CHECK(temporal::filterWith(r.weights, results).pixels == r.color.pixels);
  int drifted = 0;
  for (const temporal::NeighbourWeights& n : r.weights.neighbours)
    drifted += !n.drifted.empty() && !n.relit;
  CHECK(drifted == 1);
  // A pass whose own light differs where the colour's did not drift (its
  // leftover error, another light's share) is brought nowhere there.
  std::vector<Image> pass;
  for (const auto& f : frames) pass.push_back(f.denoised.floats());
  for (int y = 32; y < 64; ++y)
    for (int x = 0; x < 96; ++x)
      for (int c = 0; c < 3; ++c) pass[2].at(x, y, c) *= 0.9f;
  std::vector<const Image*> passes;
  for (const Image& p : pass) passes.push_back(&p);
  const Image passDrifted = temporal::filterWith(r.weights, passes);
  const Image passKept = temporal::filterWith(kept.weights, passes);
  for (int x = 0; x < 96; ++x) CHECK(passDrifted.at(x, 60, 1) == passKept.at(x, 60, 1));
}

TEST_CASE("a diffuse pass takes a drifted neighbour only where its own renders agree") {
  const Synthetic truth = makeFrame(96, 64, 0, 0);
  const std::vector<temporal::WindowFrame> frames = driftingShot(truth, 0.03f);
  temporal::TemporalOptions options;
  options.driftBox = 7;
  options.radius = 2;
  const temporal::TemporalResult r = temporal::filterFrame(windowOf(frames), 4, options);
  REQUIRE(r.stats.drifted == 1);
  // A pass of half the light; in the drifted neighbour its bottom half (where
  // the colour's light held) lost 30 %, another pass making up for it.
  std::vector<Image> pass, render;
  for (const auto& f : frames) {
    pass.push_back(f.denoised.floats()), render.push_back(f.noisy.floats());
    for (Image* image : {&pass.back(), &render.back()})
      for (float& v : image->pixels) v *= 0.5f;
  }
  std::size_t drifted = 0, steady = 0;
  for (std::size_t k = 0; k < r.weights.neighbours.size(); ++k)
    (r.weights.neighbours[k].drifted.empty() ? steady : drifted) = k;
  const temporal::NeighbourWeights& nb = r.weights.neighbours[drifted];
  for (Image* image : {&pass[nb.frame], &render[nb.frame]})
    for (int y = 32; y < 64; ++y)
      for (int x = 0; x < 96; ++x)
        for (int c = 0; c < 3; ++c) image->at(x, y, c) *= 0.7f;
  const temporal::TestedWeights tested =
      temporal::passLightTested(r.weights, pointersTo(render), pointersTo(pass), options);
  REQUIRE(tested.size() == r.weights.neighbours.size());
  CHECK(tested[steady].empty());  // its light held: the colour's weights serve
  // The drifted one keeps its weights where the pass agrees, loses them where it changed.
  // (Rows 27-37: the light test's 11x11 boxes see both halves.)
  int keptTop = 0, takenTop = 0, takenBottom = 0;
  double weightBottom = 0.0, testedBottom = 0.0;
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 96; ++x) {
      const std::size_t i = static_cast<std::size_t>(y) * 96 + x;
      if (nb.weight[i] <= 0.0) continue;
      CHECK(tested[drifted][i] <= nb.weight[i]);
      if (y < 27) takenTop += 1, keptTop += tested[drifted][i] == nb.weight[i];
      if (y < 38) continue;
      takenBottom += 1, weightBottom += nb.weight[i], testedBottom += tested[drifted][i];
    }
  CHECK(keptTop > 0.9 * takenTop);
  CHECK(takenBottom > 0.9 * 96 * 26);
  CHECK(testedBottom < 0.01 * weightBottom);
  // Filtered with them, the pass's bottom half is the frame's own light, not darker.
  const Image untested = temporal::filterWith(r.weights, pointersTo(pass));
  const Image filtered = temporal::filterWith(r.weights, pointersTo(pass), 0.0, &tested);
  double own = 0.0, before = 0.0, after = 0.0;
  for (int y = 40; y < 64; ++y)
    for (int x = 0; x < 96; ++x)
      own += pass[4].at(x, y, 1), before += untested.at(x, y, 1), after += filtered.at(x, y, 1);
  CHECK(before / own < 0.95);
  CHECK(after / own == doctest::Approx(1.0).epsilon(0.01));
  // Without a drifted neighbour, or with the test off, there is nothing to test.
  options.passLightHigh = 0.0;
  CHECK(
      temporal::passLightTested(r.weights, pointersTo(render), pointersTo(pass), options).empty());
}

TEST_CASE("temporal filter: a change of light relighting cannot undo leaves the neighbour out") {
  const Synthetic truth = makeFrame(32, 24, 0, 0);
  std::vector<temporal::WindowFrame> frames = stillShot(truth, 3, 510, 610);
  // Light changing from pixel to pixel (a flickering, dappled light): no
  // local mean brings the neighbours to the frame's light.
  std::mt19937 random(42);
  std::uniform_real_distribution<float> factor(0.4f, 2.5f);
  for (unsigned t : {0u, 2u})
    for (std::size_t i = 0; i < frames[t].denoised.pixelCount(); ++i) {
      const float f = factor(random);
      for (int c = 0; c < 3; ++c) {
        frames[t].denoised.floats().pixels[3 * i + c] *= f;
        frames[t].noisy.floats().pixels[3 * i + c] *= f;
      }
    }
  const temporal::TemporalResult r = temporal::filterFrame(windowOf(frames), 1);
  CHECK(r.stats.changedLight == 2);
  CHECK(r.stats.historyShare == 0.0);
  CHECK(r.color.pixels == frames[1].denoised.floats().pixels);
}

TEST_CASE("the environment is told by its depth (0, or beyond 1e9) and never reprojected") {
  Guides g;
  g.depth = Image(6, 1, 1);
  g.depth.pixels = {0.0f, 1e10f, std::numeric_limits<float>::infinity(), 3.0f, 1e-3f, -2.0f};
  CHECK(showsEnvironment(g, 0));
  CHECK(showsEnvironment(g, 1));
  CHECK(showsEnvironment(g, 2));
  CHECK_FALSE(showsEnvironment(g, 3));
  CHECK_FALSE(showsEnvironment(g, 4));
  CHECK_FALSE(showsEnvironment(g, 5));         // a renderer that writes -z
  CHECK_FALSE(showsEnvironment(Guides{}, 0));  // no depth: every pixel a surface

  // A still frame whose top half is the sky, in Cycles' two ways.
  const int w = 40, h = 24;
  Synthetic frame = makeFrame(w, h, 0.0, 0.0);
  for (int y = 0; y < h / 2; ++y)
    for (int x = 0; x < w; ++x) frame.depth.at(x, y, 0) = x % 2 ? 0.0f : 1e10f;
  const MotionField still = constantMotion(w, h, 0, 0, 0, 0);
  const Guides gf = guides(frame);
  const Reprojected r =
      reproject(frame.color, gf, chainPositions({{&gf, &still}, {&gf, &still}}, false), gf);
  for (int x = 0; x < w; ++x) {
    CHECK(r.trust.at(x, 2, 0) == 0.0f);
    CHECK(r.trust.at(x, h - 3, 0) == 1.0f);
  }
}

// Cycles writes zero vectors on the environment seen directly, however the
// camera turns: a pan's sky slides under vectors that say it stands still.
TEST_CASE("temporal filter: a pan's sky, its vectors zero, does not cost the ground its history") {
  // The top four fifths are the environment, sliding 3 px a frame: noiseless
  // but for the pixel filter's jitter; the rest a surface that stands still.
  const int w = 64, h = 48, sky = 4 * h / 5;
  std::vector<temporal::WindowFrame> frames;
  std::mt19937 jitter(900);
  std::normal_distribution<float> aa(0.0f, 0.002f);
  for (unsigned t = 0; t < 3; ++t) {
    const Synthetic slid = makeFrame(w, h, 3.0 * t, 0.0), still = makeFrame(w, h, 0.0, 0.0);
    temporal::WindowFrame f = stillFrame(still, 700 + t, 800 + t);
    for (int y = 0; y < sky; ++y)
      for (int x = 0; x < w; ++x) {
        f.guides.depth.floats().at(x, y, 0) = 0.0f;
        for (int c = 0; c < 3; ++c) {
          f.denoised.floats().at(x, y, c) = slid.color.at(x, y, c);
          f.noisy.floats().at(x, y, c) = slid.color.at(x, y, c) + aa(jitter);
        }
      }
    frames.push_back(std::move(f));
  }
  const temporal::TemporalResult r = temporal::filterFrame(windowOf(frames), 1);
  // The sky's mismatch is not read as a change of light over the frame.
  CHECK(r.stats.changedLight == 0);
  CHECK(r.stats.relit == 0);
  // The ground averages its neighbours in; the sky is the frame's own.
  auto rowsError = [&](const Image& image, int y0, int y1) {
    const Synthetic sliding = makeFrame(w, h, 3.0, 0.0), ground = makeFrame(w, h, 0.0, 0.0);
    double e = 0.0;
    for (int y = y0; y < y1; ++y)
      for (int x = 0; x < w; ++x)
        for (int c = 0; c < 3; ++c)
          e += std::pow(image.at(x, y, c) - (y < sky ? sliding : ground).color.at(x, y, c), 2);
    return e;
  };
  CHECK(rowsError(r.color, sky, h) < 0.7 * rowsError(frames[1].denoised.floats(), sky, h));
  CHECK(rowsError(r.color, 0, sky) == rowsError(frames[1].denoised.floats(), 0, sky));
}

TEST_CASE("temporal filter: the result does not depend on the number of threads") {
  const Synthetic truth = makeFrame(32, 24, 0, 0);
  std::vector<temporal::WindowFrame> frames = stillShot(truth, 7, 700, 800);
  const std::vector<const temporal::WindowFrame*> window = windowOf(frames);
  temporal::TemporalOptions one, four;
  one.radius = four.radius = 3;
  four.threads = 4;
  const temporal::TemporalResult a = temporal::filterFrame(window, 3, one);
  const temporal::TemporalResult b = temporal::filterFrame(window, 3, four);
  CHECK(a.stats.neighbours == 6);
  CHECK(a.color.pixels == b.color.pixels);
  CHECK(a.stats.trusted == b.stats.trusted);
}

TEST_CASE("temporal filter: a neighbour that cannot be brought in throws, threads or not") {
  const Synthetic truth = makeFrame(32, 24, 0, 0);
  std::vector<temporal::WindowFrame> frames = stillShot(truth, 3, 900, 950);
  frames[2].motion = constantMotion(16, 12, 0, 0, 0, 0);  // not the frame's size
  const std::vector<const temporal::WindowFrame*> window = windowOf(frames);
  temporal::TemporalOptions two;
  two.threads = 2;
  CHECK_THROWS_AS(temporal::filterFrame(window, 1), std::invalid_argument);
  CHECK_THROWS_AS(temporal::filterFrame(window, 1, two), std::invalid_argument);
}

namespace {

// Per frame, `image` of it, for filterWith.
std::vector<const Image*> imagesOf(const std::vector<temporal::WindowFrame>& frames,
                                   temporal::WindowImage temporal::WindowFrame::*image) {
  std::vector<const Image*> images;
  for (const auto& f : frames) images.push_back(&(f.*image).floats());
  return images;
}

// Mean over frames of the mean absolute change from the frame before.
double flicker(const std::vector<Image>& frames) {
  double sum = 0.0;
  for (std::size_t t = 1; t < frames.size(); ++t) {
    double d = 0.0;
    for (std::size_t i = 0; i < frames[t].pixels.size(); ++i)
      d += std::abs(frames[t].pixels[i] - frames[t - 1].pixels[i]);
    sum += d / frames[t].pixels.size();
  }
  return sum / (frames.size() - 1);
}

}  // namespace

TEST_CASE(
    "temporal filter: its weights filter another image of the frames as they did the results") {
  // A pan (resampled taps, the screen's edge), a still shot, and neighbours relit first.
  std::vector<temporal::WindowFrame> pan = panShot(40, 50);
  const Synthetic truth = makeFrame(32, 24, 0, 0);
  std::vector<temporal::WindowFrame> relit = brighterNeighbours(truth, 500, 600);
  for (const auto* frames : {&pan, &relit}) {
    const temporal::TemporalResult r = temporal::filterFrame(windowOf(*frames), 1);
    REQUIRE(r.weights.neighbours.size() == 2);
    const std::vector<const Image*> results = imagesOf(*frames, &temporal::WindowFrame::denoised);
    CHECK(temporal::filterWith(r.weights, results).pixels == r.color.pixels);
    // The renders accumulate as the filter accumulated them, bit for bit.
    const std::vector<const Image*> renders = imagesOf(*frames, &temporal::WindowFrame::noisy);
    Image counts;
    CHECK(temporal::accumulateWith(r.weights, renders, results, 0.0, &counts).pixels ==
          r.history.pixels);
    CHECK(counts.pixels == r.historyFrames.pixels);
    CHECK_THROWS_AS(temporal::accumulateWith(r.weights, {nullptr, nullptr, nullptr}, results),
                    std::invalid_argument);
    // A neighbour without the image is left out; alone, the frame's own is kept.
    CHECK(temporal::filterWith(r.weights, {nullptr, results[1], nullptr}).pixels ==
          results[1]->pixels);
    CHECK_THROWS_AS(temporal::filterWith(r.weights, {results[0], nullptr}), std::invalid_argument);
  }
  CHECK(temporal::filterFrame(windowOf(relit), 1).weights.neighbours[0].relit);
}

TEST_CASE("temporal filter: a light pass filtered with the results' weights flickers far less") {
  // A still shot; each frame's pass (half the light) carries a leftover error
  // of its own, as a pass denoised alone does.
  const Synthetic truth = makeFrame(32, 24, 0, 0);
  std::vector<temporal::WindowFrame> frames = stillShot(truth, 9, 300, 400);
  std::vector<Image> passes;
  for (unsigned t = 0; t < frames.size(); ++t) {
    Image pass = stillFrame(truth, 0, 450 + t).denoised.floats();
    for (float& v : pass.pixels) v *= 0.5f;
    passes.push_back(std::move(pass));
  }
  std::vector<const Image*> images;
  for (const Image& pass : passes) images.push_back(&pass);
  std::vector<Image> filtered;
  for (std::size_t t = 0; t < frames.size(); ++t)
    filtered.push_back(
        temporal::filterWith(temporal::filterFrame(windowOf(frames), t).weights, images));
  CHECK(flicker(filtered) < flicker(passes) / 3);
}

namespace {

// A still shot's light pass per frame (`share` of the light), with a leftover
// error of its own, as a pass denoised alone.
std::vector<Image> stillPass(const Synthetic& truth, unsigned count, float share, unsigned seed) {
  std::vector<Image> out;
  for (unsigned t = 0; t < count; ++t) {
    out.push_back(stillFrame(truth, seed + t, seed + 100 + t).denoised.floats());
    for (float& v : out.back().pixels) v *= share;
  }
  return out;
}

}  // namespace

TEST_CASE("a view-dependent pass takes a neighbour only where the surface stood still") {
  const Synthetic truth = makeFrame(32, 24, 0, 0);
  const std::vector<temporal::WindowFrame> still = stillShot(truth, 3, 1000, 1100);
  const std::vector<Image> pass = stillPass(truth, 3, 0.5f, 1200);
  // Still: the gate changes nothing, bit for bit.
  const temporal::FilterWeights stillWeights = temporal::filterFrame(windowOf(still), 1).weights;
  REQUIRE(stillWeights.neighbours.size() == 2);
  const std::vector<const Image*> images = pointersTo(pass);
  CHECK(temporal::filterWith(stillWeights, images, 0.5).pixels ==
        temporal::filterWith(stillWeights, images).pixels);
  // A pan of a pixel a frame: the frame's own pass, bit for bit.
  std::vector<temporal::WindowFrame> pan = panShot(40, 50);
  const temporal::FilterWeights panWeights = temporal::filterFrame(windowOf(pan), 1).weights;
  REQUIRE(panWeights.neighbours.size() == 2);
  CHECK(temporal::filterWith(panWeights, images, 0.5).pixels == pass[1].pixels);
  // Its render gathers frames where the surface stood still, none on the pan.
  Image frames;
  temporal::accumulateWith(stillWeights, images, images, 0.5, &frames);
  CHECK(*std::min_element(frames.pixels.begin(), frames.pixels.end()) > 1.5f);
  temporal::accumulateWith(panWeights, images, images, 0.5, &frames);
  CHECK(std::all_of(frames.pixels.begin(), frames.pixels.end(), [](float f) { return f == 1.0f; }));
}

TEST_CASE("a relit neighbour's pass is not taken where that pass's light came or went") {
  // A torch moved: the neighbours' beauty is relit (brighter over the frame),
  // and the torch's own pass lit the columns 8-23 there, 0-15 in the frame;
  // elsewhere its light is a hundredth (a bounce).
  const Synthetic truth = makeFrame(32, 24, 0, 0);
  const std::vector<temporal::WindowFrame> frames = brighterNeighbours(truth, 500, 600);
  const temporal::TemporalResult r = temporal::filterFrame(windowOf(frames), 1);
  REQUIRE(r.stats.relit == 2);
  std::vector<Image> pass = stillPass(truth, 3, 0.5f, 1500);
  auto litWithin = [](Image& image, int from, int to) {
    for (int y = 0; y < image.height; ++y)
      for (int x = 0; x < image.width; ++x)
        for (int c = 0; c < 3; ++c)
          if (x < from || x >= to) image.at(x, y, c) *= 0.01f;
  };
  std::vector<Image> render = stillPass(truth, 3, 0.5f, 1600);  // its noisier renders
  litWithin(pass[0], 8, 24), litWithin(pass[1], 0, 16), litWithin(pass[2], 8, 24);
  litWithin(render[0], 8, 24), litWithin(render[1], 0, 16), litWithin(render[2], 8, 24);
  const Image filtered = temporal::filterWith(r.weights, pointersTo(pass));
  const Image accumulated =
      temporal::accumulateWith(r.weights, pointersTo(render), pointersTo(pass));
  // Where a 3x3 box holds the light in one frame only, the frame's own pass and render.
  double own = 0.0, both = 0.0;
  for (int y = 0; y < 24; ++y)
    for (int x = 0; x < 32; ++x)
      for (int c = 0; c < 3; ++c) {
        if (x < 7 || (x > 16 && x < 24)) {
          CHECK(filtered.at(x, y, c) == pass[1].at(x, y, c));
          CHECK(accumulated.at(x, y, c) == render[1].at(x, y, c));
        }
        if (x < 9 || x > 14) continue;
        // Lit in all three: averaged, the leftover error falls.
        const float light = 0.5f * truth.color.at(x, y, c);
        own += std::pow(pass[1].at(x, y, c) - light, 2);
        both += std::pow(filtered.at(x, y, c) - light, 2);
      }
  CHECK(both < 0.7 * own);
}

TEST_CASE(
    "temporal filter: light that moves with the view is taken only where surfaces stood still") {
  std::vector<temporal::WindowFrame> pan = panShot(60, 70);
  const Synthetic truth = makeFrame(32, 24, 0, 0);
  std::vector<temporal::WindowFrame> still = stillShot(truth, 3, 1300, 1400);
  for (auto* frames : {&pan, &still}) {
    const temporal::TemporalResult unknown = temporal::filterFrame(windowOf(*frames), 1);
    (*frames)[1].viewDependent = Image(32, 24, 1, 0.0f);
    CHECK(temporal::filterFrame(windowOf(*frames), 1).color.pixels == unknown.color.pixels);
    (*frames)[1].viewDependent = Image(32, 24, 1, 1.0f);
    const temporal::TemporalResult mirror = temporal::filterFrame(windowOf(*frames), 1);
    if (frames == &still) {
      CHECK(mirror.color.pixels == unknown.color.pixels);
    } else {
      // A pixel a frame: an all-mirror frame is its own result alone.
      CHECK(mirror.color.pixels == (*frames)[1].denoised.floats().pixels);
      CHECK(unknown.color.pixels != (*frames)[1].denoised.floats().pixels);
    }
  }
}

namespace {

// A learned trust whose every weight is the logistic of `bias` (no weight
// on any feature): 12 -> 1.
temporal::LearnedTrust constantTrust(float bias) {
  std::vector<float> params(temporal::kTrustFeatureCount, 0.0f);
  params.push_back(bias);
  return temporal::LearnedTrust({temporal::kTrustFeatureCount, 1}, params);
}

}  // namespace

TEST_CASE("learned trust: the network computed by hand, its text round trip, bad text refused") {
  // 12 -> 2 -> 1: hidden = relu(W1 f + b1), out = logistic(W2 hidden + b2).
  std::vector<float> params(2 * temporal::kTrustFeatureCount, 0.0f);
  params[0] = 1.0f, params[1] = -2.0f;              // hidden 0
  params[temporal::kTrustFeatureCount + 2] = 0.5f;  // hidden 1
  params.insert(params.end(), {0.25f, -1.0f, /*W2*/ 3.0f, -4.0f, /*b2*/ 0.1f});
  const temporal::LearnedTrust trust({temporal::kTrustFeatureCount, 2, 1}, params);
  float f[temporal::kTrustFeatureCount] = {2.0f, 0.5f, 4.0f};
  // hidden 0 = relu(2 - 1 + 0.25) = 1.25; hidden 1 = relu(0.5 * 4 - 1) = 1.
  const double expected = 1.0 / (1.0 + std::exp(-(3.0 * 1.25 - 4.0 * 1.0 + 0.1)));
  CHECK(trust.weigh(f) == doctest::Approx(expected).epsilon(1e-6));
  f[1] = 2.0f;  // hidden 0 = relu(2 - 4 + 0.25) = 0
  CHECK(trust.weigh(f) == doctest::Approx(1.0 / (1.0 + std::exp(-(-4.0 + 0.1)))).epsilon(1e-6));

  const temporal::LearnedTrust again = temporal::LearnedTrust::fromText(trust.toText());
  CHECK(again.toText() == trust.toText());
  CHECK(again.weigh(f) == trust.weigh(f));
  CHECK_THROWS_AS(temporal::LearnedTrust::fromText("12 2 1 0.5"), std::invalid_argument);
  CHECK_THROWS_AS(temporal::LearnedTrust::fromText("12 2 1 : 0.5"), std::invalid_argument);
  CHECK_THROWS_AS(temporal::LearnedTrust({11, 1}, std::vector<float>(12)), std::invalid_argument);
}

TEST_CASE("learned trust: trusting nothing gives the frame alone; its view is what it weighs") {
  const Synthetic truth = makeFrame(32, 24, 0, 0);
  std::vector<temporal::WindowFrame> frames = stillShot(truth, 5, 900, 1000);
  temporal::TemporalOptions options;
  options.learnedTrust = std::make_shared<temporal::LearnedTrust>(constantTrust(-100.0f));
  const temporal::TemporalResult none = temporal::filterFrame(windowOf(frames), 2, options);
  CHECK(none.color.pixels == frames[2].denoised.floats().pixels);

  // Trusting fully: each neighbour weighs what the rules gave it, and the
  // observer sees every kept neighbour's features and those weights.
  options.learnedTrust = std::make_shared<temporal::LearnedTrust>(constantTrust(100.0f));
  std::vector<temporal::TrustSamples> seen;
  options.observeTrust = [&](const temporal::TrustSamples& s) { seen.push_back(s); };
  const temporal::TemporalResult all = temporal::filterFrame(windowOf(frames), 2, options);
  REQUIRE(seen.size() == 1);
  const temporal::TrustSamples& s = seen.front();
  CHECK(s.frames == std::vector<std::size_t>{1, 0, 3, 4});
  REQUIRE(s.weights.size() == 4);
  for (std::size_t k = 0; k < 4; ++k)
    for (std::size_t i = 0; i < s.weights[k].size(); ++i) {
      const float* f = &s.features[k][i * temporal::kTrustFeatureCount];
      CHECK(s.weights[k][i] == all.weights.neighbours[k].weight[i]);
      CHECK((s.weights[k][i] == 0.0 || f[temporal::kGuideTrust] > 0.0f));
      CHECK(f[temporal::kDistance] == (k == 0 || k == 2 ? 0.25f : 0.5f));
      CHECK(f[temporal::kFuture] == (k >= 2 ? 1.0f : 0.0f));
    }
  CHECK(all.color.pixels == temporal::filterFrame(windowOf(frames), 2).color.pixels);
}

TEST_CASE("learned trust: the rules' weights reach the observer as they filter") {
  const Synthetic truth = makeFrame(32, 24, 0, 0);
  std::vector<temporal::WindowFrame> frames = stillShot(truth, 3, 1100, 1200);
  temporal::TemporalOptions options;
  std::vector<temporal::TrustSamples> seen;
  options.observeTrust = [&](const temporal::TrustSamples& s) { seen.push_back(s); };
  const temporal::TemporalResult r = temporal::filterFrame(windowOf(frames), 1, options);
  REQUIRE(seen.size() == 1);
  REQUIRE(seen[0].weights.size() == r.weights.neighbours.size());
  for (std::size_t k = 0; k < seen[0].weights.size(); ++k)
    CHECK(seen[0].weights[k] == r.weights.neighbours[k].weight);
  // Observing changes nothing.
  CHECK(r.color.pixels == temporal::filterFrame(windowOf(frames), 1).color.pixels);
}
