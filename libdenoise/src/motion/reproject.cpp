#include "dn/motion/reproject.h"

#include <cmath>
#include <limits>
#include <stdexcept>

namespace dn::motion {

namespace {

constexpr float kLost = std::numeric_limits<float>::quiet_NaN();

bool onScreen(float x, float y, int width, int height) {
  return x >= -0.5f && y >= -0.5f && x <= width - 0.5f && y <= height - 0.5f;
}

int nearest(float v, int size) {
  const int i = static_cast<int>(std::lround(v));
  return i < 0 ? 0 : (i >= size ? size - 1 : i);
}

// Whether pixel `s` of the source and pixel `c` of the current frame see the
// same surface, by every guide both frames have.
bool sameSurface(const Guides& source, std::size_t s, const Guides& current, std::size_t c,
                 const TrustOptions& o) {
  if (!source.depth.empty() && !current.depth.empty()) {
    const float zs = source.depth.pixels[s], zc = current.depth.pixels[c];
    if (std::abs(zs - zc) > o.depthRelative * std::max(std::abs(zc), 1e-6f)) return false;
  }
  if (!source.normal.empty() && !current.normal.empty()) {
    const float* ns = &source.normal.pixels[3 * s];
    const float* nc = &current.normal.pixels[3 * c];
    const double ls = std::sqrt(ns[0] * ns[0] + ns[1] * ns[1] + ns[2] * ns[2]);
    const double lc = std::sqrt(nc[0] * nc[0] + nc[1] * nc[1] + nc[2] * nc[2]);
    if ((ls < 1e-3) != (lc < 1e-3)) return false;  // surface against background
    if (ls >= 1e-3 && (ns[0] * nc[0] + ns[1] * nc[1] + ns[2] * nc[2]) < o.normalCosine * ls * lc)
      return false;
  }
  if (!source.albedo.empty() && !current.albedo.empty()) {
    for (int ch = 0; ch < 3; ++ch) {
      const float as = source.albedo.pixels[3 * s + ch], ac = current.albedo.pixels[3 * c + ch];
      if (std::abs(as - ac) > o.albedoAbsolute + o.albedoRelative * std::max(as, ac)) return false;
    }
  }
  return true;
}

void checkGuides(const Guides& g, int width, int height) {
  for (const Image* image : {&g.albedo, &g.normal, &g.depth})
    if (!image->empty() && (image->width != width || image->height != height))
      throw std::invalid_argument("reproject: a guide is not the frame's size");
}

}  // namespace

Image chainPositions(const std::vector<FrameGeometry>& chain, bool forward,
                     const TrustOptions& options) {
  if (chain.size() < 2) throw std::invalid_argument("chainPositions: needs two frames or more");
  const int width = chain.front().motion->width(), height = chain.front().motion->height();
  for (const auto& frame : chain)
    if (!frame.motion || frame.motion->empty() || frame.motion->width() != width ||
        frame.motion->height() != height)
      throw std::invalid_argument("chainPositions: every frame needs motion of the same size");
  Image positions(width, height, 2);
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) {
      float qx = static_cast<float>(x), qy = static_cast<float>(y);
      for (std::size_t hop = 0; hop + 1 < chain.size() && !std::isnan(qx); ++hop) {
        const Image& there = forward ? chain[hop].motion->toNext : chain[hop].motion->toPrevious;
        const float* off = there.pixel(nearest(qx, width), nearest(qy, height));
        const float nx = qx + off[0], ny = qy + off[1];
        if (!onScreen(nx, ny, width, height)) {
          qx = qy = kLost;
          break;
        }
        // The neighbour's own motion back must return here: where it does not,
        // the neighbour shows something else at that place (an occluder).
        const Image& back =
            forward ? chain[hop + 1].motion->toPrevious : chain[hop + 1].motion->toNext;
        const float* ret = back.pixel(nearest(nx, width), nearest(ny, height));
        const float ex = nx + ret[0] - qx, ey = ny + ret[1] - qy;
        if (ex * ex + ey * ey > options.roundTripPixels * options.roundTripPixels) {
          qx = qy = kLost;
          break;
        }
        qx = nx, qy = ny;
      }
      positions.at(x, y, 0) = qx;
      positions.at(x, y, 1) = qy;
    }
  return positions;
}

Reprojected reproject(const Image& source, const Guides& sourceGuides, const Image& positions,
                      const Guides& currentGuides, const TrustOptions& options) {
  const int width = positions.width, height = positions.height, channels = source.channels;
  if (source.width != width || source.height != height || positions.channels != 2)
    throw std::invalid_argument("reproject: source and positions differ in size");
  checkGuides(sourceGuides, width, height);
  checkGuides(currentGuides, width, height);
  Reprojected out{Image(width, height, channels), Image(width, height, 1)};
  std::vector<double> sum(channels);
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) {
      const float qx = positions.at(x, y, 0), qy = positions.at(x, y, 1);
      if (std::isnan(qx) || std::isnan(qy)) continue;
      const int x0 = static_cast<int>(std::floor(qx)), y0 = static_cast<int>(std::floor(qy));
      const float fx = qx - x0, fy = qy - y0;
      const std::size_t here = static_cast<std::size_t>(y) * width + x;
      double accepted = 0.0;
      std::fill(sum.begin(), sum.end(), 0.0);
      for (int t = 0; t < 4; ++t) {
        const int tx = x0 + (t & 1), ty = y0 + (t >> 1);
        const double bilinear = ((t & 1) ? fx : 1.0f - fx) * ((t >> 1) ? fy : 1.0f - fy);
        const bool closest =
            tx == static_cast<int>(std::lround(qx)) && ty == static_cast<int>(std::lround(qy));
        const double w = options.nearest ? (closest ? 1.0 : 0.0) : bilinear;
        if (w <= 0.0 || tx < 0 || ty < 0 || tx >= width || ty >= height) continue;
        const std::size_t tap = static_cast<std::size_t>(ty) * width + tx;
        if (!sameSurface(sourceGuides, tap, currentGuides, here, options)) continue;
        accepted += w;
        for (int c = 0; c < channels; ++c) sum[c] += w * source.pixels[tap * channels + c];
      }
      if (accepted < options.minCoverage) continue;
      for (int c = 0; c < channels; ++c)
        out.image.pixels[here * channels + c] = static_cast<float>(sum[c] / accepted);
      out.trust.pixels[here] = static_cast<float>(std::min(1.0, accepted));
    }
  return out;
}

Image reprojectNearest(const Image& source, const Image& positions) {
  Image out(positions.width, positions.height, source.channels);
  for (int y = 0; y < positions.height; ++y)
    for (int x = 0; x < positions.width; ++x) {
      const float qx = positions.at(x, y, 0), qy = positions.at(x, y, 1);
      if (std::isnan(qx) || std::isnan(qy)) continue;
      const float* from = source.pixel(nearest(qx, source.width), nearest(qy, source.height));
      std::copy(from, from + source.channels, out.pixel(x, y));
    }
  return out;
}

}  // namespace dn::motion
