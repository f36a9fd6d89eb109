#include "dn/motion/reproject.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace dn::motion {

namespace {

constexpr float kLost = std::numeric_limits<float>::quiet_NaN();

bool onScreen(float x, float y, int width, int height) {
  return x >= -0.5f && y >= -0.5f && x <= width - 0.5f && y <= height - 0.5f;
}

// std::lround(v) clamped to [0, size): halves away from zero, without a call.
int nearest(float v, int size) {
  if (!(v >= 0.5f)) return 0;  // also NaN
  if (v >= size - 0.5f) return size - 1;
  const int i = static_cast<int>(v);  // v - i is exact below 2^24
  return v - static_cast<float>(i) >= 0.5f ? i + 1 : i;
}

// The guide if present: null where absent or empty.
const Image* present(const Image* guide) { return guide && !guide->empty() ? guide : nullptr; }

// A frame's guides (null where absent) and each pixel's normal length: the
// normal test compares directions at every tap, so the lengths are taken
// once per plan.
struct Surface {
  const Image *albedo, *normal, *depth;
  std::vector<float> normalLength;
  explicit Surface(const GuideImages& g)
      : albedo(present(g.albedo)), normal(present(g.normal)), depth(present(g.depth)) {
    if (!normal) return;
    normalLength.resize(normal->pixelCount());
    for (std::size_t i = 0; i < normalLength.size(); ++i) {
      const float* n = &normal->pixels[3 * i];
      normalLength[i] = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    }
  }
};

// showsEnvironment, by a depth guide that may be null.
bool environmentAt(const Image* depth, std::size_t pixel) {
  if (!depth) return false;
  const float z = depth->pixels[pixel];
  return z == 0.0f || !(std::abs(z) < 1e9f);  // also infinite or NaN
}

// A pixel of the current frame as the guide tests compare source taps with
// it, its values taken once for all of a pixel's taps.
struct Target {
  float depth = 0.0f;
  double depthLimit = 0.0;  // the largest depth difference of the same surface
  const float* normal = nullptr;
  double normalLength = 0.0;
  const float* albedo = nullptr;
};

Target targetOf(const Surface& current, std::size_t c, const TrustOptions& o) {
  Target t;
  if (current.depth) {
    t.depth = current.depth->pixels[c];
    t.depthLimit = o.depthRelative * std::max(std::abs(t.depth), 1e-6f);
  }
  if (current.normal)
    t.normal = &current.normal->pixels[3 * c], t.normalLength = current.normalLength[c];
  if (current.albedo) t.albedo = &current.albedo->pixels[3 * c];
  return t;
}

// Whether pixel `s` of the source and the target see the same surface by
// depth, by normal, by albedo.
bool sameDepth(const Surface& source, std::size_t s, const Target& t, const TrustOptions&) {
  return std::abs(source.depth->pixels[s] - t.depth) <= t.depthLimit;
}

bool sameNormal(const Surface& source, std::size_t s, const Target& t, const TrustOptions& o) {
  const float* ns = &source.normal->pixels[3 * s];
  const float* nc = t.normal;
  const double ls = source.normalLength[s], lc = t.normalLength;
  if ((ls < 1e-3) != (lc < 1e-3)) return false;  // surface against background
  return ls < 1e-3 || (ns[0] * nc[0] + ns[1] * nc[1] + ns[2] * nc[2]) >= o.normalCosine * ls * lc;
}

bool sameAlbedo(const Surface& source, std::size_t s, const Target& t, const TrustOptions& o) {
  for (int ch = 0; ch < 3; ++ch) {
    const float as = source.albedo->pixels[3 * s + ch], ac = t.albedo[ch];
    if (std::abs(as - ac) > o.albedoAbsolute + o.albedoRelative * std::max(as, ac)) return false;
  }
  return true;
}

// Which guide tests apply: those whose guide both frames have.
struct GuideTests {
  bool depth, normal, albedo;
  GuideTests(const Surface& a, const Surface& b)
      : depth(a.depth && b.depth), normal(a.normal && b.normal), albedo(a.albedo && b.albedo) {}
};

// A guide test passed at the target (current pixel `c`) or at a pixel within
// `neighbourhood` of it. An edge pixel's guides blend two surfaces by a
// coverage that every frame's anti-aliasing samples change, so the tap is
// compared with each surface seen around it, not with this frame's blend
// alone. (A template, so that the test is inlined: this runs for every tap
// of every pixel.)
template <class GuideTest>
bool matchesAround(GuideTest test, const Surface& source, std::size_t s, const Target& target,
                   const Surface& current, std::size_t c, int width, int height,
                   const TrustOptions& o) {
  if (test(source, s, target, o)) return true;
  const int r = o.neighbourhood, cx = static_cast<int>(c % width), cy = static_cast<int>(c / width);
  for (int y = std::max(0, cy - r); y <= std::min(height - 1, cy + r); ++y)
    for (int x = std::max(0, cx - r); x <= std::min(width - 1, cx + r); ++x) {
      const std::size_t k = static_cast<std::size_t>(y) * width + x;
      if (k != c && test(source, s, targetOf(current, k, o), o)) return true;
    }
  return false;
}

// Whether source pixel `s` shows a surface seen at or around current pixel
// `c` (the target), by every guide both frames have (albedo only when `byAlbedo`).
bool sameSurface(const Surface& source, std::size_t s, const Target& target, const Surface& current,
                 std::size_t c, const GuideTests& tests, int width, int height,
                 const TrustOptions& o, bool byAlbedo = true) {
  if (tests.depth && !matchesAround(sameDepth, source, s, target, current, c, width, height, o))
    return false;
  if (tests.normal && !matchesAround(sameNormal, source, s, target, current, c, width, height, o))
    return false;
  return !byAlbedo || !tests.albedo ||
         matchesAround(sameAlbedo, source, s, target, current, c, width, height, o);
}

// Catmull-Rom's weights of the taps at offsets -1, 0, 1, 2 from floor(q).
std::array<double, 4> catmullRom(double t) {
  const double t2 = t * t, t3 = t2 * t;
  return {0.5 * (-t3 + 2 * t2 - t), 0.5 * (3 * t3 - 5 * t2 + 2), 0.5 * (-3 * t3 + 4 * t2 + t),
          0.5 * (t3 - t2)};
}

// Whether Catmull-Rom may resample at (qx, qy): all 16 taps lie on the
// screen and show the destination's surface by depth and normal (a texture's
// edges within one surface are what it keeps sharp). The bilinear taps in
// `matched` (Resampling::taps' bits) passed those tests already.
bool cubicTapsMatch(const Surface& sourceGuides, float qx, float qy, const Target& target,
                    const Surface& currentGuides, std::size_t here, const GuideTests& tests,
                    int width, int height, const TrustOptions& options, unsigned char matched) {
  const int x0 = static_cast<int>(std::floor(qx)) - 1, y0 = static_cast<int>(std::floor(qy)) - 1;
  if (x0 < 0 || y0 < 0 || x0 + 3 >= width || y0 + 3 >= height) return false;
  for (int j = 0; j < 4; ++j)
    for (int i = 0; i < 4; ++i) {
      // The middle four are the bilinear taps: those `matched` passed already.
      const bool middle = (i == 1 || i == 2) && (j == 1 || j == 2);
      if (middle && (matched & (1u << ((i - 1) + 2 * (j - 1))))) continue;
      const std::size_t tap = static_cast<std::size_t>(y0 + j) * width + x0 + i;
      if (!sameSurface(sourceGuides, tap, target, currentGuides, here, tests, width, height,
                       options, false))
        return false;
    }
  return true;
}

// cubicSample of `Count` images of 3 channels (a result, and its history),
// as cubicSample sums them but with the sums held in registers: the same bits.
template <int Count>
bool cubicSampleRgb(const std::vector<const Image*>& sources, float qx, float qy,
                    const std::vector<float*>& out) {
  const int width = sources.front()->width;
  const int x0 = static_cast<int>(std::floor(qx)) - 1, y0 = static_cast<int>(std::floor(qy)) - 1;
  const auto wx = catmullRom(qx - (x0 + 1)), wy = catmullRom(qy - (y0 + 1));
  std::array<const float*, Count> from;
  for (int k = 0; k < Count; ++k) from[k] = sources[k]->pixels.data();
  double sum[3 * Count] = {};
  for (int j = 0; j < 4; ++j)
    for (int i = 0; i < 4; ++i) {
      const std::size_t tap = 3 * (static_cast<std::size_t>(y0 + j) * width + x0 + i);
      const double w = wx[i] * wy[j];
      for (int k = 0; k < Count; ++k)
        for (int c = 0; c < 3; ++c) sum[3 * k + c] += w * from[k][tap + c];
    }
  for (double v : sum)
    if (v < 0.0) return false;
  for (int k = 0; k < Count; ++k)
    for (int c = 0; c < 3; ++c) out[k][c] = static_cast<float>(sum[3 * k + c]);
  return true;
}

// The sources resampled at (qx, qy) by Catmull-Rom into `out` (each
// source's channels at its own pointer), whose taps cubicTapsMatch allowed;
// false, with `out` untouched, where a value of any would be negative (an
// overshoot at a dark edge) or they hold more than 8 channels together.
bool cubicSample(const std::vector<const Image*>& sources, float qx, float qy,
                 const std::vector<float*>& out) {
  const bool rgb = std::all_of(sources.begin(), sources.end(),
                               [](const Image* source) { return source->channels == 3; });
  if (rgb && sources.size() == 1) return cubicSampleRgb<1>(sources, qx, qy, out);
  if (rgb && sources.size() == 2) return cubicSampleRgb<2>(sources, qx, qy, out);
  const int width = sources.front()->width;
  const int x0 = static_cast<int>(std::floor(qx)) - 1, y0 = static_cast<int>(std::floor(qy)) - 1;
  int channels = 0;
  for (const Image* source : sources) channels += source->channels;
  if (channels > 8) return false;
  const auto wx = catmullRom(qx - (x0 + 1)), wy = catmullRom(qy - (y0 + 1));
  std::array<double, 8> sum = {};
  for (int j = 0; j < 4; ++j)
    for (int i = 0; i < 4; ++i) {
      const std::size_t tap = static_cast<std::size_t>(y0 + j) * width + x0 + i;
      double* to = sum.data();
      for (const Image* source : sources)
        for (int c = 0; c < source->channels; ++c)
          *to++ += wx[i] * wy[j] * source->pixels[tap * source->channels + c];
    }
  for (int c = 0; c < channels; ++c)
    if (sum[c] < 0.0) return false;
  const double* from = sum.data();
  for (std::size_t k = 0; k < sources.size(); ++k)
    for (int c = 0; c < sources[k]->channels; ++c) out[k][c] = static_cast<float>(*from++);
  return true;
}

// The bits of Resampling::taps beyond the four bilinear taps'.
constexpr unsigned char kCubicTaps = 1u << 4;
constexpr unsigned char kBroughtIn = 1u << 5;

// The four bilinear taps of the pixel at (qx, qy), in the order of
// Resampling::taps' bits: each one's index and weight; the weight is 0 where
// the tap is off the image.
struct BilinearTaps {
  std::array<std::size_t, 4> index;
  std::array<double, 4> weight;
};
inline BilinearTaps bilinearTaps(float qx, float qy, int width, int height) {
  const int x0 = static_cast<int>(std::floor(qx)), y0 = static_cast<int>(std::floor(qy));
  const float fx = qx - x0, fy = qy - y0;
  BilinearTaps taps{};
  for (int t = 0; t < 4; ++t) {
    const int tx = x0 + (t & 1), ty = y0 + (t >> 1);
    const double w = ((t & 1) ? fx : 1.0f - fx) * ((t >> 1) ? fy : 1.0f - fy);
    if (w <= 0.0 || tx < 0 || ty < 0 || tx >= width || ty >= height) continue;
    taps.index[t] = static_cast<std::size_t>(ty) * width + tx;
    taps.weight[t] = w;
  }
  return taps;
}

void checkGuides(const GuideImages& g, int width, int height) {
  for (const Image* image : {g.albedo, g.normal, g.depth})
    if (present(image) && (image->width != width || image->height != height))
      throw std::invalid_argument("reproject: a guide is not the frame's size");
}

}  // namespace

std::vector<Image> chainPositionsAlong(const std::vector<FrameGeometry>& chain, bool forward,
                                       const TrustOptions& options) {
  if (chain.size() < 2) throw std::invalid_argument("chainPositions: needs two frames or more");
  const int width = chain.front().motion->width(), height = chain.front().motion->height();
  std::vector<Image> positions(chain.size() - 1, Image(width, height, 2));
  chainPositionsRows(chain, forward, options, 0, height, positions);
  return positions;
}

void chainPositionsRows(const std::vector<FrameGeometry>& chain, bool forward,
                        const TrustOptions& options, int rowBegin, int rowEnd,
                        std::vector<Image>& positions) {
  if (chain.size() < 2) throw std::invalid_argument("chainPositions: needs two frames or more");
  const int width = chain.front().motion->width(), height = chain.front().motion->height();
  for (const auto& frame : chain)
    if (!frame.motion || frame.motion->empty() || frame.motion->width() != width ||
        frame.motion->height() != height)
      throw std::invalid_argument("chainPositions: every frame needs motion of the same size");
  if (positions.size() != chain.size() - 1)
    throw std::invalid_argument("chainPositions: one image of positions a hop");
  if (rowBegin < 0 || rowEnd > height || rowBegin > rowEnd)
    throw std::invalid_argument("chainPositions: rows outside the frame");
  for (const Image& p : positions)
    if (p.width != width || p.height != height || p.channels != 2)
      throw std::invalid_argument("chainPositions: positions differ from the motion in size");
  // Hop after hop over the rows, each from the positions the hop before
  // reached: a few images are read at a time, not all of the chain's.
  for (std::size_t hop = 0; hop + 1 < chain.size(); ++hop) {
    const Image& there = forward ? chain[hop].motion->toNext : chain[hop].motion->toPrevious;
    // The neighbour's own motion back must return here: where it does not,
    // the neighbour shows something else at that place (an occluder).
    const Image& back = forward ? chain[hop + 1].motion->toPrevious : chain[hop + 1].motion->toNext;
    for (int y = rowBegin; y < rowEnd; ++y)
      for (int x = 0; x < width; ++x) {
        float qx = static_cast<float>(x), qy = static_cast<float>(y);
        if (hop > 0) qx = positions[hop - 1].at(x, y, 0), qy = positions[hop - 1].at(x, y, 1);
        if (!std::isnan(qx)) {
          const float* off = there.pixel(nearest(qx, width), nearest(qy, height));
          const float nx = qx + off[0], ny = qy + off[1];
          const float* ret = onScreen(nx, ny, width, height)
                                 ? back.pixel(nearest(nx, width), nearest(ny, height))
                                 : nullptr;
          const float ex = ret ? nx + ret[0] - qx : 0.0f, ey = ret ? ny + ret[1] - qy : 0.0f;
          if (!ret || ex * ex + ey * ey > options.roundTripPixels * options.roundTripPixels)
            qx = qy = kLost;
          else
            qx = nx, qy = ny;
        }
        positions[hop].at(x, y, 0) = qx;
        positions[hop].at(x, y, 1) = qy;
      }
  }
}

Image chainPositions(const std::vector<FrameGeometry>& chain, bool forward,
                     const TrustOptions& options) {
  return std::move(chainPositionsAlong(chain, forward, options).back());
}

Resampling planResampling(const GuideImages& sourceGuides, Image positionsIn,
                          const GuideImages& currentGuides, const TrustOptions& options) {
  const int width = positionsIn.width, height = positionsIn.height;
  if (positionsIn.channels != 2)
    throw std::invalid_argument("reproject: positions need 2 channels");
  checkGuides(sourceGuides, width, height);
  checkGuides(currentGuides, width, height);
  const std::size_t pixels = positionsIn.pixelCount();
  Resampling plan{std::move(positionsIn), std::vector<unsigned char>(pixels, 0),
                  Image(width, height, 1)};
  const Image& positions = plan.positions;
  const Surface source(sourceGuides), current(currentGuides);
  const GuideTests tests(source, current);
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) {
      const std::size_t here = static_cast<std::size_t>(y) * width + x;
      const float qx = positions.at(x, y, 0), qy = positions.at(x, y, 1);
      if (std::isnan(qx) || std::isnan(qy) || environmentAt(current.depth, here)) continue;
      double accepted = 0.0;
      unsigned char taps = 0;
      const Target target = targetOf(current, here, options);
      const BilinearTaps bilinear = bilinearTaps(qx, qy, width, height);
      for (int t = 0; t < 4; ++t) {
        if (bilinear.weight[t] <= 0.0 || !sameSurface(source, bilinear.index[t], target, current,
                                                      here, tests, width, height, options))
          continue;
        accepted += bilinear.weight[t];
        taps |= static_cast<unsigned char>(1u << t);
      }
      if (accepted < options.minCoverage) continue;
      taps |= kBroughtIn;
      // Where every bilinear tap matched, the sharper cubic where it can (at a
      // whole-pixel offset both are the tap itself).
      const float fx = qx - static_cast<int>(std::floor(qx));
      const float fy = qy - static_cast<int>(std::floor(qy));
      const bool whole = (fx == 0.0f || fx == 1.0f) && (fy == 0.0f || fy == 1.0f);
      if (options.cubic && !whole && accepted > 0.999 &&
          cubicTapsMatch(source, qx, qy, target, current, here, tests, width, height, options,
                         taps))
        taps |= kCubicTaps;
      plan.taps[here] = taps;
      plan.trust.pixels[here] = static_cast<float>(std::min(1.0, accepted));
    }
  return plan;
}

std::vector<Image> resample(const Resampling& plan, const std::vector<const Image*>& sources) {
  const int width = plan.positions.width, height = plan.positions.height;
  std::vector<Image> out;
  for (const Image* source : sources) {
    if (source->width != width || source->height != height)
      throw std::invalid_argument("reproject: source and positions differ in size");
    out.emplace_back(width, height, source->channels);
  }
  std::vector<float*> value(sources.size());
  for (std::size_t here = 0; here < plan.taps.size(); ++here) {
    const unsigned char taps = plan.taps[here];
    if (!(taps & kBroughtIn)) continue;
    const float qx = plan.positions.pixels[2 * here], qy = plan.positions.pixels[2 * here + 1];
    for (std::size_t k = 0; k < sources.size(); ++k)
      value[k] = &out[k].pixels[here * sources[k]->channels];
    if ((taps & kCubicTaps) && cubicSample(sources, qx, qy, value)) continue;
    const BilinearTaps bilinear = bilinearTaps(qx, qy, width, height);
    double accepted = 0.0;
    for (int t = 0; t < 4; ++t)
      if (taps & (1u << t)) accepted += bilinear.weight[t];
    for (std::size_t k = 0; k < sources.size(); ++k) {
      const Image& source = *sources[k];
      for (int c = 0; c < source.channels; ++c) {
        double sum = 0.0;
        for (int t = 0; t < 4; ++t)
          if (taps & (1u << t))
            sum += bilinear.weight[t] * source.pixels[bilinear.index[t] * source.channels + c];
        value[k][c] = static_cast<float>(sum / accepted);
      }
    }
  }
  return out;
}

Image resample(const Resampling& plan, const Image& source) {
  return std::move(resample(plan, std::vector<const Image*>{&source}).front());
}

Reprojected reproject(const Image& source, const Guides& sourceGuides, const Image& positions,
                      const Guides& currentGuides, const TrustOptions& options) {
  if (source.width != positions.width || source.height != positions.height ||
      positions.channels != 2)
    throw std::invalid_argument("reproject: source and positions differ in size");
  Resampling plan = planResampling(sourceGuides, positions, currentGuides, options);
  return {resample(plan, source), std::move(plan.trust)};
}

bool showsEnvironment(const Guides& guides, std::size_t pixel) {
  return environmentAt(present(&guides.depth), pixel);
}

Image reprojectNearest(const Image& source, const Image& positions) {
  Image out(positions.width, positions.height, source.channels);
  reprojectNearestRows(source, positions, 0, positions.height, out);
  return out;
}

void reprojectNearestRows(const Image& source, const Image& positions, int rowBegin, int rowEnd,
                          Image& out) {
  for (int y = rowBegin; y < rowEnd; ++y)
    for (int x = 0; x < positions.width; ++x) {
      float* to = out.pixel(x, y);
      const float qx = positions.at(x, y, 0), qy = positions.at(x, y, 1);
      if (std::isnan(qx) || std::isnan(qy)) {
        std::fill_n(to, source.channels, 0.0f);
        continue;
      }
      const float* from = source.pixel(nearest(qx, source.width), nearest(qy, source.height));
      std::copy(from, from + source.channels, to);
    }
}

std::vector<std::int32_t> nearestPixels(const Image& positions, int width, int height) {
  std::vector<std::int32_t> out(positions.pixelCount(), -1);
  for (std::size_t i = 0; i < out.size(); ++i) {
    const float qx = positions.pixels[2 * i], qy = positions.pixels[2 * i + 1];
    if (!std::isnan(qx) && !std::isnan(qy))
      out[i] = nearest(qy, height) * width + nearest(qx, width);
  }
  return out;
}

}  // namespace dn::motion
