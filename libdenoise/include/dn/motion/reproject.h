// Bringing a neighbouring frame into the current one along the motion vectors,
// and deciding per pixel whether what arrives can be trusted.
#pragma once

#include <cstdint>
#include <vector>

#include "dn/image.h"
#include "dn/motion/motion.h"

namespace dn::motion {

// The nearly noise-free first-hit features that tell whether two pixels see the
// same surface. Any may be empty (that test is then skipped).
struct Guides {
  Image albedo;  // 3 channels
  Image normal;  // 3 channels, world space
  Image depth;   // 1 channel, camera distance
};

// The same by reference, for callers that hold the images otherwise; null
// or empty: that test is skipped.
struct GuideImages {
  const Image* albedo = nullptr;
  const Image* normal = nullptr;
  const Image* depth = nullptr;
  GuideImages() = default;
  GuideImages(const Image* a, const Image* n, const Image* d) : albedo(a), normal(n), depth(d) {}
  GuideImages(const Guides& g) : albedo(&g.albedo), normal(&g.normal), depth(&g.depth) {}
};

// The rejection thresholds (docs/dndenoise.md, "Temporal denoising").
struct TrustOptions {
  double depthRelative = 0.05;   // |z' - z| / z beyond this: another surface
  double normalCosine = 0.9;     // n' . n below this: another surface or orientation
  double albedoAbsolute = 0.08;  // per channel, plus albedoRelative x the larger
  double albedoRelative = 0.25;
  double roundTripPixels = 1.0;  // the neighbour's motion back must land within this
  double minCoverage = 0.5;      // least bilinear weight of the accepted taps
  // A tap passes each guide's test if it passes it at the destination or at a
  // pixel within this many pixels of it: anti-aliased edges blend two surfaces
  // by a coverage that changes with every frame's samples.
  int neighbourhood = 1;
  // Catmull-Rom over 4x4 taps where all show the destination's surface (by
  // depth and normal), else bilinear: bilinear resampling blurs texture edges
  // by up to a quarter of their contrast at half-pixel offsets.
  bool cubic = true;
};

// One frame as reprojection sees it: its guides and its motion.
struct FrameGeometry {
  const Guides* guides = nullptr;
  const MotionField* motion = nullptr;
};

// Where each pixel of frame `chain[0]` is in frame `chain.back()`, following
// the motion hop by hop (chain[i] -> chain[i+1] are consecutive frames, forward
// in time when `forward`). A 2-channel image of positions (pixel centres at
// integers); NaN where the surface left the screen or a hop's round trip
// failed (a disocclusion: the neighbour's own motion back does not return).
Image chainPositions(const std::vector<FrameGeometry>& chain, bool forward,
                     const TrustOptions& options = {});
// The same for every frame of the chain after the first, in one pass along
// it: element k is chainPositions of chain[0 .. k + 1], bit for bit.
std::vector<Image> chainPositionsAlong(const std::vector<FrameGeometry>& chain, bool forward,
                                       const TrustOptions& options = {});
// The same into rows [rowBegin, rowEnd) of `positions` (chain.size() - 1
// images of 2 channels, the frames' size), the other rows untouched: for
// callers that split the rows among threads.
void chainPositionsRows(const std::vector<FrameGeometry>& chain, bool forward,
                        const TrustOptions& options, int rowBegin, int rowEnd,
                        std::vector<Image>& positions);

// A neighbour's image resampled at `positions` (bilinear over the taps whose
// guides match the current frame's around the destination pixel; Catmull-Rom
// where all 16 of its taps do and `cubic`), and the trust of
// each pixel in [0, 1]: 0 off-screen, disoccluded, another surface, or the
// environment (showsEnvironment); else the share of bilinear weight that
// matched (below minCoverage: 0).
struct Reprojected {
  Image image;  // channels of `source`; zeros where trust is 0
  Image trust;  // 1 channel
};
Reprojected reproject(const Image& source, const Guides& sourceGuides, const Image& positions,
                      const Guides& currentGuides, const TrustOptions& options = {});

// Which taps reproject takes at each pixel, decided once by the guides, so
// that any image of the same neighbour (a light pass) is brought in with the
// same taps and the same weights as `source` was, without the guide tests:
// reproject(image, ...) == {resample(plan, image), plan.trust}, bit for bit.
struct Resampling {
  Image positions;  // as given to planResampling
  // Per pixel: bits 0-3 the bilinear taps whose surface matched (none: not
  // brought in), bit 4 Catmull-Rom's 16 taps all matched (cubic allowed
  // where no channel of its result is negative).
  std::vector<unsigned char> taps;
  Image trust;  // reproject's
  bool empty() const { return taps.empty(); }
};
Resampling planResampling(const GuideImages& sourceGuides, Image positions,
                          const GuideImages& currentGuides, const TrustOptions& options = {});
// `source` (any channel count) brought in by `plan`; zeros where trust is 0.
Image resample(const Resampling& plan, const Image& source);
// Several images brought in together, as one image of their channels
// stacked would be: Catmull-Rom only where no channel of any overshoots below 0.
std::vector<Image> resample(const Resampling& plan, const std::vector<const Image*>& sources);

// Nearest-pixel resampling (no filtering: noise stays uncorrelated), for the
// repeated-noise test. Zeros where positions are NaN.
Image reprojectNearest(const Image& source, const Image& positions);
// The same into rows [rowBegin, rowEnd) of `out` (positions' size, source's
// channels), the other rows untouched: for callers that split the rows among threads.
void reprojectNearestRows(const Image& source, const Image& positions, int rowBegin, int rowEnd,
                          Image& out);
// Per pixel of `positions`, the index of the pixel of a width x height image
// that reprojectNearest takes, or -1 where positions are NaN: for callers that
// bring in several images, or values made from them, at the nearest pixel.
std::vector<std::int32_t> nearestPixels(const Image& positions, int width, int height);

// Whether `pixel` shows no surface, only the environment: a depth guide of 0
// (Cycles' Denoising Depth, Mitsuba's) or beyond 1e9 (Cycles' Z pass writes
// 1e10). It is never reprojected: the environment seen directly has no Monte
// Carlo noise for history to average away, and a renderer's vectors there may
// not follow the camera (Cycles writes zero however it turns). Not a zero
// normal: Cycles' normal guide follows glass and mirrors to the sky, and there
// the render is noisy.
bool showsEnvironment(const Guides& guides, std::size_t pixel);

}  // namespace dn::motion
