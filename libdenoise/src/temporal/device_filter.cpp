#include "dn/temporal/device_filter.h"

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <tuple>

#include "dn/nn/model_inputs.h"

namespace dn::temporal {

namespace {

using torch::Tensor;
namespace F = torch::nn::functional;

// reproject.cpp's bits of Resampling::taps beyond the four bilinear taps'.
constexpr int kCubicTaps = 1 << 4;
constexpr int kBroughtIn = 1 << 5;

// The frame's pixel grid, computed once a frame: coordinates and the sizes.
struct Grid {
  int width, height;
  Tensor x, y;  // float per pixel
  std::int64_t pixels() const { return std::int64_t(width) * height; }
};

// `options`: float on the frames' device.
Grid gridOf(int width, int height, const torch::TensorOptions& options) {
  const Tensor xs = torch::arange(width, options), ys = torch::arange(height, options);
  const auto xy = torch::meshgrid({ys, xs}, "ij");
  return {width, height, xy[1].reshape(-1), xy[0].reshape(-1)};
}

// `values` where `keep` holds, else 0.
Tensor onlyWhere(const Tensor& keep, const Tensor& values) {
  return torch::where(keep, values, torch::zeros_like(values));
}

// tonemapped() of temporal_filter.cpp: Reinhard after `scale`; NaN: 0, beyond 1e30: 1.
Tensor tonemapped(const Tensor& linear, const Tensor& scale) {
  const Tensor s = linear * scale;
  const Tensor positive = onlyWhere(s > 0, s);
  return torch::where(positive < 1e30, positive / (positive + 1), torch::ones_like(s));
}

// Per pixel, the mean over channels of |a - b|.
Tensor absoluteDifference(const Tensor& a, const Tensor& b) { return (a - b).abs().mean(0); }

// Sums of `values` (rows, columns) over the ranges [starts[k], ends[k]) of
// dimension `dim`, from a running sum: deterministic on CUDA, unlike atomics.
Tensor rangeSums(const Tensor& values, int dim, const Tensor& starts, const Tensor& ends) {
  std::vector<std::int64_t> shape(values.sizes().begin(), values.sizes().end());
  shape[dim] = 1;
  const Tensor running =
      torch::cat({torch::zeros(shape, values.options()), values.cumsum(dim)}, dim);
  return running.index_select(dim, ends) - running.index_select(dim, starts);
}

// OIDN's autoexposure (tonemap::oidnExposure): 0.18 over the geometric mean of
// the luminance's means over bins of about 16 x 16 pixels.
Tensor exposureOf(const Tensor& color, int width, int height) {
  constexpr int kBin = 16;
  const int binsY = (height + kBin - 1) / kBin, binsX = (width + kBin - 1) / kBin;
  std::vector<std::int64_t> y0(binsY), y1(binsY), x0(binsX), x1(binsX);
  std::vector<float> counts;
  for (int by = 0; by < binsY; ++by)
    y0[by] = by * height / binsY, y1[by] = (by + 1) * height / binsY;
  for (int bx = 0; bx < binsX; ++bx) x0[bx] = bx * width / binsX, x1[bx] = (bx + 1) * width / binsX;
  for (int by = 0; by < binsY; ++by)
    for (int bx = 0; bx < binsX; ++bx)
      counts.push_back(float((y1[by] - y0[by]) * (x1[bx] - x0[bx])));
  const auto device = color.device();
  auto onDevice = [&](const std::vector<std::int64_t>& v) { return torch::tensor(v).to(device); };
  const Tensor clean = torch::where(torch::isfinite(color), color.clamp_min(0),
                                    onlyWhere(color > 0, torch::full_like(color, FLT_MAX)));
  const Tensor luminance =
      (0.212671f * clean[0] + 0.715160f * clean[1] + 0.072169f * clean[2]).view({height, width});
  const Tensor byRow = rangeSums(luminance.to(torch::kDouble), 0, onDevice(y0), onDevice(y1));
  const Tensor sums = rangeSums(byRow, 1, onDevice(x0), onDevice(x1));
  const Tensor mean =
      (sums.to(torch::kFloat) / torch::tensor(counts).to(device).view({binsY, binsX}));
  const Tensor valid = mean > 1e-8f;
  const Tensor logSum = onlyWhere(valid, torch::log2(mean)).sum(torch::kDouble);
  const Tensor count = valid.sum();
  return torch::where(count > 0, 0.18 / torch::exp2(logSum / count.clamp_min(1)),
                      torch::ones_like(logSum))
      .to(torch::kFloat);
}

// The box of (2r+1)^2 pixels around each pixel, clipped to the image: its
// first and last row and column (one past), per row and per column.
struct Box {
  Tensor y0, y1, x0, x1;
};

Box boxOf(int r, const Grid& g, const torch::Device& device) {
  const auto longs = torch::TensorOptions().dtype(torch::kLong).device(device);
  const Tensor ys = torch::arange(g.height, longs), xs = torch::arange(g.width, longs);
  return {(ys - r).clamp_min(0), (ys + r + 1).clamp_max(g.height), (xs - r).clamp_min(0),
          (xs + r + 1).clamp_max(g.width)};
}

// Per pixel, the sums of `values` (channels, pixels) over its box, in double
// from integral images, as temporal_filter.cpp's BoxSums.
Tensor boxSum(const Tensor& values, int r, const Grid& g) {
  const std::int64_t channels = values.size(0);
  const Tensor integral =
      F::pad(values.to(torch::kDouble).view({channels, g.height, g.width}).cumsum(1).cumsum(2),
             F::PadFuncOptions({1, 0, 1, 0}));
  const Box box = boxOf(r, g, values.device());
  auto corner = [&](const Tensor& ys, const Tensor& xs) {
    return integral.index_select(1, ys).index_select(2, xs);
  };
  const Tensor sums = corner(box.y1, box.x1) - corner(box.y0, box.x1) - corner(box.y1, box.x0) +
                      corner(box.y0, box.x0);
  return sums.view({channels, g.pixels()});
}

// Per pixel, the number of pixels in its box (double).
Tensor boxPixels(int r, const Grid& g, const torch::Device& device) {
  const Box box = boxOf(r, g, device);
  return ((box.y1 - box.y0).unsqueeze(1) * (box.x1 - box.x0).unsqueeze(0))
      .to(torch::kDouble)
      .view({g.pixels()});
}

// Per pixel, the means of `values` over its box (double).
Tensor boxMean(const Tensor& values, int r, const Grid& g) {
  return boxSum(values, r, g) / boxPixels(r, g, values.device());
}

// std::lround, clamped to [0, size): NaN gives 0 (callers mask it). The
// fraction v - trunc(v) is exact in float, so halves round away from zero
// as lround's do (floor(v + 0.5) would round 0.49999997 up).
Tensor nearest(const Tensor& v, int size) {
  const Tensor finite = torch::nan_to_num(v, 0.0), whole = torch::trunc(finite);
  const Tensor rounded = whole + onlyWhere((finite - whole).abs() >= 0.5f, finite.sign());
  return rounded.clamp(0, size - 1).to(torch::kLong);
}

Tensor nearestPixel(const Tensor& qx, const Tensor& qy, const Grid& g) {
  return nearest(qy, g.height) * g.width + nearest(qx, g.width);
}

Tensor lost(const Tensor& positions) {
  return torch::isnan(positions[0]) | torch::isnan(positions[1]);
}

// reprojectNearest: zeros where the position is lost.
Tensor reprojectNearest(const Tensor& source, const Tensor& positions, const Grid& g) {
  const Tensor moved = source.index_select(1, nearestPixel(positions[0], positions[1], g));
  return onlyWhere(~lost(positions), moved);
}

// motion::chainPositions along `chain` (the centre first).
Tensor chainPositions(const std::vector<const DeviceFrame*>& chain, bool forward,
                      const motion::TrustOptions& options, const Grid& g) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  Tensor qx = g.x, qy = g.y;
  const double limit = options.roundTripPixels * options.roundTripPixels;
  for (std::size_t hop = 0; hop + 1 < chain.size(); ++hop) {
    const Tensor& there = forward ? chain[hop]->toNext : chain[hop]->toPrevious;
    const Tensor offset = there.index_select(1, nearestPixel(qx, qy, g));
    const Tensor nx = qx + offset[0], ny = qy + offset[1];
    const Tensor onScreen =
        (nx >= -0.5f) & (ny >= -0.5f) & (nx <= g.width - 0.5f) & (ny <= g.height - 0.5f);
    // The neighbour's own motion back must return here (else an occluder).
    const Tensor& back = forward ? chain[hop + 1]->toPrevious : chain[hop + 1]->toNext;
    const Tensor ret = back.index_select(1, nearestPixel(nx, ny, g));
    const Tensor ex = nx + ret[0] - qx, ey = ny + ret[1] - qy;
    const Tensor kept = onScreen & ~((ex * ex + ey * ey).to(torch::kDouble) > limit);
    qx = torch::where(kept, nx, torch::full_like(nx, nan));
    qy = torch::where(kept, ny, torch::full_like(ny, nan));
  }
  return torch::stack({qx, qy});
}

// The centre frame's guides for the surface tests, and each pixel's
// neighbourhood: a tap passes a guide's test where it passes it at the pixel
// or at one within `neighbourhood` of it (reproject.cpp's matchesAround).
struct CentreGuides {
  // depthLimit: depthRelative x |z| in double, rounded down to float;
  // normalLength in double.
  Tensor depth, depthLimit, normal, normalLength, albedo;
  // (offsets, pixels): the pixels around each, and which of them lie on the image.
  Tensor around, aroundValid;
  Tensor environment;  // per pixel: showsEnvironment
};

Tensor normalLength(const Tensor& normal) {
  return torch::sqrt(normal[0] * normal[0] + normal[1] * normal[1] + normal[2] * normal[2]);
}

CentreGuides centreGuides(const DeviceFrame& frame, const motion::TrustOptions& trust,
                          const Grid& g) {
  const int r = trust.neighbourhood;
  std::vector<Tensor> indices, valid;
  const Tensor x = g.x.to(torch::kLong), y = g.y.to(torch::kLong);
  for (int dy = -r; dy <= r; ++dy)
    for (int dx = -r; dx <= r; ++dx) {
      const Tensor ox = x + dx, oy = y + dy;
      valid.push_back((ox >= 0) & (oy >= 0) & (ox < g.width) & (oy < g.height));
      indices.push_back(oy.clamp(0, g.height - 1) * g.width + ox.clamp(0, g.width - 1));
    }
  CentreGuides out{frame.depth,         {}, frame.normal, {}, frame.albedo, torch::stack(indices),
                   torch::stack(valid), {}};
  if (frame.normal.defined()) out.normalLength = normalLength(frame.normal).to(torch::kDouble);
  if (frame.depth.defined()) {
    // The largest float not above the double limit: a float difference
    // passes it exactly where it passes the double one.
    const Tensor limit =
        trust.depthRelative * frame.depth.abs().clamp_min(1e-6f).to(torch::kDouble);
    const Tensor rounded = limit.to(torch::kFloat);
    out.depthLimit =
        torch::where(rounded.to(torch::kDouble) > limit,
                     torch::nextafter(rounded, torch::full_like(rounded, -INFINITY)), rounded);
  }
  out.environment = frame.depth.defined()
                        ? (frame.depth[0] == 0) | ~(frame.depth[0].abs() < 1e9f)
                        : torch::zeros({g.pixels()}, frame.denoised.options().dtype(torch::kBool));
  return out;
}

// `image` (channels, pixels) at `index` (any shape): (channels, ...index's shape).
Tensor gather(const Tensor& image, const Tensor& index) {
  std::vector<std::int64_t> shape = {image.size(0)};
  shape.insert(shape.end(), index.sizes().begin(), index.sizes().end());
  return image.index_select(1, index.reshape(-1)).view(shape);
}

// One guide's test of the source's pixels `s` against the centre's pixels
// `at` (index tensors whose shapes broadcast). Differences and products in
// float, the thresholds in double, as reproject.cpp computes them:
// half-float guides make exact ties common.
enum class Guide { Depth, Normal, Albedo };

Tensor guideTest(Guide guide, const DeviceFrame& source, const CentreGuides& c, const Tensor& s,
                 const Tensor& at, const motion::TrustOptions& o) {
  switch (guide) {
    case Guide::Depth:
      return ((gather(source.depth, s) - gather(c.depth, at)).abs() <= gather(c.depthLimit, at))[0];
    case Guide::Normal: {
      const Tensor ns = gather(source.normal, s), nc = gather(c.normal, at);
      const Tensor ls = normalLength(ns).to(torch::kDouble);
      const Tensor lc = gather(c.normalLength.unsqueeze(0), at)[0];
      const Tensor dot = (ns[0] * nc[0] + ns[1] * nc[1] + ns[2] * nc[2]).to(torch::kDouble);
      const Tensor background = ls < 1e-3;
      return (background == (lc < 1e-3)) & (background | (dot >= o.normalCosine * ls * lc));
    }
    case Guide::Albedo: {
      const Tensor as = gather(source.albedo, s), ac = gather(c.albedo, at);
      const Tensor limit =
          o.albedoAbsolute + o.albedoRelative * torch::max(as, ac).to(torch::kDouble);
      return (~((as - ac).abs().to(torch::kDouble) > limit)).all(0);
    }
  }
  throw std::logic_error("guideTest: an unknown guide");
}

bool bothHave(Guide guide, const DeviceFrame& source, const CentreGuides& c) {
  switch (guide) {
    case Guide::Depth:
      return source.depth.defined() && c.depth.defined();
    case Guide::Normal:
      return source.normal.defined() && c.normal.defined();
    case Guide::Albedo:
      return source.albedo.defined() && c.albedo.defined();
  }
  return false;
}

// Per tap and destination (`taps`: (count, destinations) source pixels,
// `destinations` the centre's pixels), whether the tap passes `guide`'s test
// at the destination or at a pixel around it. Most pass at the destination
// itself: only the others are tested around it, one copy to the host to
// count them.
Tensor passesAround(Guide guide, const DeviceFrame& source, const CentreGuides& c,
                    const Tensor& taps, const Tensor& destinations, const motion::TrustOptions& o) {
  const std::int64_t count = taps.size(0), n = taps.size(1);
  if (!bothHave(guide, source, c)) return torch::ones({count, n}, c.environment.options());
  Tensor passes = guideTest(guide, source, c, taps, destinations.unsqueeze(0), o).reshape(-1);
  const Tensor failed = (~passes).nonzero().squeeze(1);
  if (failed.numel() > 0) {
    const Tensor pixel = destinations.index_select(0, failed.remainder(n));
    const Tensor tap = taps.reshape(-1).index_select(0, failed).unsqueeze(0);
    const Tensor near = guideTest(guide, source, c, tap, c.around.index_select(1, pixel), o);
    passes = passes.index_put({failed}, (near & c.aroundValid.index_select(1, pixel)).any(0));
  }
  return passes.view({count, n});
}

// reproject.cpp's sameSurface over `taps` (count, destinations): depth and
// normal, and the albedo where `byAlbedo`.
Tensor sameSurface(const DeviceFrame& source, const CentreGuides& c, const Tensor& taps,
                   const Tensor& destinations, const motion::TrustOptions& o, bool byAlbedo) {
  Tensor passes = passesAround(Guide::Depth, source, c, taps, destinations, o) &
                  passesAround(Guide::Normal, source, c, taps, destinations, o);
  if (byAlbedo) passes = passes & passesAround(Guide::Albedo, source, c, taps, destinations, o);
  return passes;
}

// The 4 x 4 taps around a position: tap (i, j) at floor(q) - 1 + (i, j).
struct Taps {
  Tensor x0, y0;  // floor(q), long
  Tensor fx, fy;  // q - floor(q)
  Tensor usable;  // the position is not lost
  Tensor index(int i, int j, const Grid& g) const {
    return (y0 - 1 + j).clamp(0, g.height - 1) * g.width + (x0 - 1 + i).clamp(0, g.width - 1);
  }
  Tensor inside(int i, int j, const Grid& g) const {
    const Tensor x = x0 - 1 + i, y = y0 - 1 + j;
    return (x >= 0) & (y >= 0) & (x < g.width) & (y < g.height);
  }
  // Bilinear tap t (0-3): (t & 1, t >> 1) from floor(q); weight 0 off the image.
  Tensor bilinearWeight(int t, const Grid& g) const {
    const Tensor w = ((t & 1) ? fx : 1.0f - fx) * ((t >> 1) ? fy : 1.0f - fy);
    return onlyWhere(usable & inside(1 + (t & 1), 1 + (t >> 1), g) & (w > 0), w);
  }
  Tensor bilinearIndex(int t, const Grid& g) const { return index(1 + (t & 1), 1 + (t >> 1), g); }
};

Taps tapsOf(const Tensor& positions) {
  const Tensor usable = ~lost(positions);
  const Tensor qx = torch::nan_to_num(positions[0], 0.0), qy = torch::nan_to_num(positions[1], 0.0);
  const Tensor fx0 = torch::floor(qx), fy0 = torch::floor(qy);
  return {fx0.to(torch::kLong), fy0.to(torch::kLong), qx - fx0, qy - fy0, usable};
}

// Where Catmull-Rom may resample among `candidates`: its 12 outer taps show
// the destination's surface by depth and normal (the inner 4, the bilinear
// taps, were tested already).
Tensor outerTapsMatch(const DeviceFrame& source, const CentreGuides& c, const Taps& taps,
                      const Tensor& candidates, const motion::TrustOptions& o, const Grid& g) {
  const Tensor pixels = candidates.nonzero().squeeze(1);
  if (pixels.numel() == 0) return candidates;
  std::vector<Tensor> outer;
  for (int j = 0; j < 4; ++j)
    for (int i = 0; i < 4; ++i)
      if (i == 0 || i == 3 || j == 0 || j == 3)
        outer.push_back(taps.index(i, j, g).index_select(0, pixels));
  const Tensor match = sameSurface(source, c, torch::stack(outer), pixels, o, false).all(0);
  return candidates.index_put({pixels}, match);
}

// motion::planResampling on the device.
DeviceResampling planResampling(const DeviceFrame& source, const Tensor& positions,
                                const CentreGuides& c, const motion::TrustOptions& o,
                                const Grid& g) {
  const Taps taps = tapsOf(positions);
  std::vector<Tensor> indices;
  for (int t = 0; t < 4; ++t) indices.push_back(taps.bilinearIndex(t, g));
  const Tensor all = torch::arange(g.pixels(), indices[0].options());
  const Tensor shape = sameSurface(source, c, torch::stack(indices), all, o, false);
  const Tensor albedo = passesAround(Guide::Albedo, source, c, torch::stack(indices), all, o);
  Tensor accepted = torch::zeros({g.pixels()}, positions.options().dtype(torch::kDouble));
  Tensor bits = torch::zeros({g.pixels()}, positions.options().dtype(torch::kInt));
  for (int t = 0; t < 4; ++t) {  // in reproject.cpp's order: the same sums
    const Tensor weight = taps.bilinearWeight(t, g);
    const Tensor matched = (weight > 0) & shape[t] & albedo[t];
    accepted = accepted + onlyWhere(matched, weight.to(torch::kDouble));
    bits = bits | onlyWhere(matched, torch::full_like(bits, 1 << t));
  }
  const Tensor brought = taps.usable & ~c.environment & (accepted >= o.minCoverage);
  Tensor cubic = torch::zeros_like(brought);
  if (o.cubic) {
    // Where every bilinear tap matched, the sharper cubic where all 16 of its
    // taps lie on the image and show the destination's surface.
    const Tensor whole = ((taps.fx == 0) | (taps.fx == 1)) & ((taps.fy == 0) | (taps.fy == 1));
    cubic = outerTapsMatch(source, c, taps,
                           brought & ~whole & (accepted > 0.999) & taps.inside(0, 0, g) &
                               taps.inside(3, 3, g) & shape.all(0),
                           o, g);
  }
  bits = bits | onlyWhere(cubic, torch::full_like(bits, kCubicTaps));
  bits = onlyWhere(brought, bits | kBroughtIn);
  const Tensor trust = onlyWhere(brought, accepted.clamp_max(1.0)).to(torch::kFloat);
  return {positions, bits.to(torch::kUInt8), trust};
}

// Catmull-Rom's weights of the taps at offsets -1, 0, 1, 2 from floor(q).
std::vector<Tensor> catmullRom(const Tensor& t) {
  const Tensor t2 = t * t, t3 = t2 * t;
  return {0.5f * (-t3 + 2 * t2 - t), 0.5f * (3 * t3 - 5 * t2 + 2), 0.5f * (-3 * t3 + 4 * t2 + t),
          0.5f * (t3 - t2)};
}

// motion::resample on the device: `source` (any channels) brought in by `plan`.
Tensor resample(const DeviceResampling& plan, const Tensor& source, const Grid& g) {
  const Taps taps = tapsOf(plan.positions);
  const Tensor bits = plan.taps.to(torch::kInt);
  Tensor sum = torch::zeros({source.size(0), g.pixels()}, source.options());
  Tensor accepted = torch::zeros({g.pixels()}, source.options());
  for (int t = 0; t < 4; ++t) {
    const Tensor used = (bits & (1 << t)) != 0;
    const Tensor weight = onlyWhere(used, taps.bilinearWeight(t, g));
    accepted = accepted + weight;
    sum = sum + weight * source.index_select(1, taps.index(1 + (t & 1), 1 + (t >> 1), g));
  }
  const Tensor brought = (bits & kBroughtIn) != 0;
  Tensor out =
      onlyWhere(brought, sum / torch::where(brought, accepted, torch::ones_like(accepted)));
  const Tensor cubicTaps = (bits & kCubicTaps) != 0;
  // reproject.cpp's cubic takes at most 8 channels.
  if (source.size(0) > 8 || !cubicTaps.any().item<bool>()) return out;
  // The 16-tap gather: where a channel would be negative (an overshoot at a
  // dark edge), the bilinear value stays.
  const std::vector<Tensor> wx = catmullRom(taps.fx), wy = catmullRom(taps.fy);
  Tensor cubic = torch::zeros_like(sum);
  for (int j = 0; j < 4; ++j)
    for (int i = 0; i < 4; ++i)
      cubic = cubic + (wx[i] * wy[j]) * source.index_select(1, taps.index(i, j, g));
  const Tensor sharper = cubicTaps & ~(cubic < 0).any(0);  // NaN stays cubic, as there
  return torch::where(sharper, cubic, out);
}

// Per pixel, how far its surface moved on screen (NaN: left it).
Tensor movedPixels(const Tensor& positions, const Grid& g) {
  return torch::hypot(positions[0] - g.x, positions[1] - g.y);
}

// Per pixel, how still the surface stood: 1 where it did not move, 0 from `pixels` on.
Tensor stillness(const Tensor& positions, double pixels, const Grid& g) {
  const Tensor moved = movedPixels(positions, g);
  return onlyWhere(moved < pixels, 1.0f - moved / float(pixels));
}

// The centre frame's view for the tests, computed once a frame.
struct Centre {
  const DeviceFrame* frame;
  Grid grid;
  Tensor scale;                          // its autoexposure, 0-d
  Tensor mapped, noisyMapped, residual;  // its result and render tonemapped; their difference
  Tensor noise;                          // the residual's local level, floored
  CentreGuides guides;
};

Tensor localNoise(const Tensor& residual, int r, const Grid& g) {
  return torch::sqrt(boxMean((residual * residual).mean(0, true), r, g))[0].to(torch::kFloat);
}

// The k-th smallest (1-based) of `values`.
Tensor kth(const Tensor& values, std::int64_t k) { return std::get<0>(torch::kthvalue(values, k)); }

Centre centreOf(const DeviceFrame& frame, const motion::TrustOptions& trust) {
  Centre c{&frame, gridOf(frame.width, frame.height, frame.denoised.options()), {}, {}, {}, {}, {},
           {}};
  c.scale = exposureOf(frame.denoised, frame.width, frame.height);
  c.mapped = tonemapped(frame.denoised, c.scale);
  c.noisyMapped = tonemapped(frame.noisy, c.scale);
  c.residual = c.noisyMapped - c.mapped;
  c.noise = localNoise(c.residual, 3, c.grid);
  // A floor: flat, noise-free regions (a clear sky) must not divide by zero.
  const Tensor median = kth(c.noise, c.noise.numel() / 2 + 1);
  c.noise = torch::maximum(c.noise, (0.1f * median).clamp_min(1e-4f));
  c.guides = centreGuides(frame, trust, c.grid);
  return c;
}

// Correlation of two residuals over the pixels where `trust` > 0 (host: a verdict).
double correlation(const Tensor& a, const Tensor& b, const Tensor& trust) {
  const Tensor mask = (trust > 0).to(torch::kDouble);
  const Tensor u = a.to(torch::kDouble) * mask, v = b.to(torch::kDouble);
  const Tensor sums = torch::stack({(u * v).sum(), (u * u).sum(), (v * v * mask).sum()}).cpu();
  const double ab = sums[0].item<double>(), aa = sums[1].item<double>(),
               bb = sums[2].item<double>();
  return aa > 0.0 && bb > 0.0 ? ab / std::sqrt(aa * bb) : 0.0;
}

// The spread of the leftover errors from the lower quartile of `d` over trusted pixels.
double robustSpread(const Tensor& d, const Tensor& trust) {
  const Tensor values = d.masked_select(trust > 0);
  if (values.numel() == 0) return 0.0;
  return kth(values, values.numel() / 4 + 1).item<double>() / 0.3186;
}

Tensor normalisedDifference(const Centre& centre, const Tensor& image) {
  return absoluteDifference(tonemapped(image, centre.scale), centre.mapped) / centre.noise;
}

// Per pixel and channel, the mean of `image` over the box's trusted pixels; -1 where none.
Tensor trustedBoxMean(const Tensor& image, const Tensor& trusted, int r, const Grid& g) {
  const Tensor count = boxSum(trusted.unsqueeze(0), r, g);
  const Tensor sums = boxSum(image * trusted.to(torch::kFloat), r, g);
  return torch::where(count > 0, sums / count.clamp_min(1), torch::full_like(sums, -1.0))
      .to(torch::kFloat);
}

// temporal_filter.cpp's: 0 in every channel where the boxes' light differs
// by more than `range` times either way (not taken: relitWeight).
Tensor relightFactor(const Tensor& moved, const Tensor& own, const Tensor& trust, int r,
                     double range, const Grid& g) {
  const Tensor a = trustedBoxMean(own, trust > 0, r, g), b = trustedBoxMean(moved, trust > 0, r, g);
  const float low = static_cast<float>(1.0 / range), high = static_cast<float>(range);
  const Tensor ratio =
      torch::where((a >= 0) & (b > 1e-6f), (a / b).clamp(low, high), torch::ones_like(a));
  const Tensor ownLight = a.to(torch::kDouble).sum(0), movedLight = b.to(torch::kDouble).sum(0);
  const Tensor unlit =
      (a[0] >= 0) & ((ownLight > range * movedLight) | (movedLight > range * ownLight));
  return torch::where(unlit.unsqueeze(0), torch::zeros_like(ratio), ratio);
}

// temporal_filter.cpp's: the wide boxes' ratio over the pixels `weight`
// takes, where their light departs from 1 by more than `threshold`, or, given
// `where` (bool per pixel), at its pixels; else 1.
Tensor driftFactor(const Tensor& moved, const Tensor& own, const Tensor& weight, int r,
                   double threshold, const Grid& g, const Tensor& where = {}) {
  const Tensor taken = weight > 0;
  const Tensor a = trustedBoxMean(own, taken, r, g), b = trustedBoxMean(moved, taken, r, g);
  Tensor drifted = a[0] >= 0;
  if (where.defined()) {
    drifted = drifted & where;
  } else {
    const Tensor ownLight = a.to(torch::kDouble).sum(0), movedLight = b.to(torch::kDouble).sum(0);
    drifted = drifted & (movedLight > 0) &
              ((ownLight / movedLight.clamp_min(1e-300) - 1.0).abs() > threshold);
  }
  const Tensor ones = torch::ones_like(a);
  const Tensor ratio = torch::where(b > 1e-6f, (a / b).clamp(0.5f, 2.0f), ones);
  return torch::where(drifted.unsqueeze(0), ratio, ones);
}

// `weight` where relightFactor gave `factor` a ratio, 0 where it did not.
Tensor relitWeight(const Tensor& weight, const Tensor& factor) {
  return torch::where(factor[0] == 0, torch::zeros_like(weight), weight);
}

// The renders' light test: per pixel, standard errors of the box means' difference.
Tensor lightChange(const Tensor& current, const Tensor& moved, const Tensor& trust,
                   const Tensor& currentResidual, const Tensor& movedResidual, int r,
                   const Grid& g) {
  const Tensor mask = (trust > 0).to(torch::kFloat);
  const Tensor difference = (moved - current).mean(0) * mask;
  const Tensor variance =
      (currentResidual * currentResidual + movedResidual * movedResidual).sum(0) / 9.0f * mask;
  const Tensor sums = boxSum(torch::stack({mask, difference, variance}), r, g);
  const Tensor n = sums[0], d = sums[1], v = sums[2];
  const Tensor defined = (n >= 1) & (v > 0);
  const Tensor safeN = n.clamp_min(1), safeV = torch::where(defined, v, torch::ones_like(v));
  return onlyWhere(defined, (d / safeN).abs() / (torch::sqrt(safeV) / safeN)).to(torch::kFloat);
}

// The mean of `values` over the pixels where `trust` > 0 (0 where none is).
double trustedMean(const Tensor& values, const Tensor& trust) {
  const Tensor mask = trust > 0;
  const double count = mask.sum().item<double>();
  return count > 0 ? values.masked_select(mask).to(torch::kDouble).sum().item<double>() / count
                   : 0.0;
}

struct Contribution {
  enum class Verdict { Used, Relit, RepeatedNoise, ChangedLight } verdict = Verdict::Used;
  Tensor image, history, historyWeight;
  DeviceResampling resampling;
  Tensor relight, lightChange, weight;
  Tensor drifted;  // bool per pixel: where driftFactor changed `relight`, after the tests
  double spread = 0.0, fullSpread = 0.0;
  bool used() const { return weight.defined(); }
};

Contribution contributionOf(const Centre& centre, const DeviceFrame& neighbour,
                            const std::vector<const DeviceFrame*>& chain, bool forward,
                            const TemporalOptions& options) {
  const Grid& g = centre.grid;
  Contribution out;
  const Tensor positions = chainPositions(chain, forward, options.trust, g);
  // Only the past carries a denoised history (a frame's result must not
  // depend on how far its successors have got); it counts where the surface
  // stood still, which pastHistoriesOf weighs.
  const bool withHistory = !forward && neighbour.history.defined();
  DeviceResampling plan = planResampling(neighbour, positions, centre.guides, options.trust, g);
  Tensor moved = resample(
      plan, withHistory ? torch::cat({neighbour.denoised, neighbour.history}) : neighbour.denoised,
      g);
  if (withHistory) {
    out.history = moved.slice(0, 3, 6);
    out.historyWeight = stillness(positions, options.historyMotion, g);
    moved = moved.slice(0, 0, 3);
  }
  const Tensor& trust = plan.trust;
  const Tensor neighbourNoisy = tonemapped(neighbour.noisy, centre.scale);
  const Tensor residual =
      reprojectNearest(neighbourNoisy - tonemapped(neighbour.denoised, centre.scale), positions, g);
  if (correlation(centre.residual, residual, trust) > options.repeatedNoiseCorrelation) {
    out.verdict = Contribution::Verdict::RepeatedNoise;
    return out;
  }
  out.image = moved;
  Tensor light = lightChange(centre.noisyMapped, reprojectNearest(neighbourNoisy, positions, g),
                             trust, centre.residual, residual, options.lightBox, g);
  double fullSpread = robustSpread(normalisedDifference(centre, out.image), trust);
  Tensor relitTrust;  // relit: where its factor is defined
  // A change of light over most of the frame: relit first, left out whole
  // if that does not bring the spread down (temporal_filter.cpp).
  if (fullSpread > options.changedLightSpread ||
      trustedMean(light, trust) > options.changedLightMean) {
    out.relight = relightFactor(out.image, centre.frame->denoised, trust, options.relightBox,
                                options.relightRange, g);
    out.image = out.image * out.relight;
    if (out.history.defined()) out.history = out.history * out.relight;
    relitTrust = relitWeight(trust, out.relight);
    fullSpread = robustSpread(normalisedDifference(centre, out.image), relitTrust);
    if (fullSpread > options.changedLightSpread) {
      out.verdict = Contribution::Verdict::ChangedLight;
      return out;
    }
    out.verdict = Contribution::Verdict::Relit;
  }
  out.fullSpread = fullSpread;
  out.spread = std::min(fullSpread, options.maxSpread);
  // The renders' own light test would see the change that relighting undid.
  if (out.relight.defined()) {
    out.weight = relitTrust;
    out.resampling = std::move(plan);
    return out;
  }
  out.lightChange = std::move(light);
  out.weight =
      trust * ((options.lightHigh - out.lightChange) / (options.lightHigh - options.lightLow))
                  .clamp(0.0, 1.0);
  out.resampling = std::move(plan);
  return out;
}

struct Weighted {
  const Tensor* image;
  const Tensor* weight;
};

// The frame's own (weight 1) and the others, weighted per pixel: the mean and the total weight.
std::pair<Tensor, Tensor> weightedMean(const Tensor& own, const std::vector<Weighted>& others) {
  Tensor sum = own.clone(), total = torch::ones({own.size(1)}, own.options());
  for (const Weighted& k : others) {
    const Tensor w = onlyWhere(*k.weight > 0, *k.weight);
    sum = sum + w * *k.image;
    total = total + w;
  }
  return {sum / total, total};
}

std::vector<Weighted> usedOf(const std::vector<Contribution>& contributions) {
  std::vector<Weighted> out;
  for (const Contribution& k : contributions)
    if (k.used()) out.push_back({&k.image, &k.weight});
  return out;
}

// The colour test (applyColourTest of temporal_filter.cpp).
void applyColourTest(Contribution& k, const Tensor& referenceMapped, const Centre& centre,
                     const TemporalOptions& options) {
  if (!k.used() || k.spread <= 0.0) return;
  const Tensor z = absoluteDifference(tonemapped(k.image, centre.scale), referenceMapped) /
                   centre.noise / float(k.spread);
  const Tensor factor =
      ((options.colourHigh - z) / (options.colourHigh - options.colourLow)).clamp(0.0, 1.0);
  k.weight = torch::where(k.weight > 0, k.weight * factor, k.weight);
}

// The frame's result and every kept neighbour's, weighted by the guides'
// trust alone, tonemapped: what the learned trust compares each with.
Tensor guideMean(const Centre& centre, const std::vector<Contribution>& contributions) {
  std::vector<Weighted> others;
  for (const Contribution& k : contributions)
    if (k.used()) others.push_back({&k.image, &k.resampling.trust});
  return tonemapped(weightedMean(centre.frame->denoised, others).first, centre.scale);
}

// Per pixel, the learned trust's view of neighbour `k`: (pixels, kTrustFeatureCount).
Tensor trustFeatures(const Centre& centre, const Contribution& k, const Tensor& meanMapped,
                     int distance, bool forward) {
  const Grid& g = centre.grid;
  const Tensor mapped = tonemapped(k.image, centre.scale);
  const Tensor toOwn = absoluteDifference(mapped, centre.mapped) / centre.noise;
  const Tensor toMean = absoluteDifference(mapped, meanMapped) / centre.noise;
  const Tensor moved = movedPixels(k.resampling.positions, g);
  auto constant = [&](double v) { return torch::full_like(toOwn, float(v)); };
  std::vector<Tensor> f(kTrustFeatureCount);
  f[kGuideTrust] = k.resampling.trust;
  f[kOwnDifference] = torch::log1p(toOwn);
  f[kOwnDifferenceBox] = torch::log1p(boxMean(toOwn.unsqueeze(0), 1, g)[0]).to(torch::kFloat);
  f[kMeanDifference] = torch::log1p(toMean);
  f[kLightChange] = k.lightChange.defined() ? torch::log1p(k.lightChange) : constant(0.0);
  f[kMotion] = onlyWhere(torch::isfinite(moved),
                         torch::log1p(torch::nan_to_num(moved, 0.0).clamp_max(1e3f)));
  f[kDistance] = constant(distance / 4.0);
  f[kNoiseLevel] = torch::log(centre.noise);
  f[kSpread] = constant(std::min(k.fullSpread, 3.0));
  f[kRelit] = constant(k.relight.defined() ? 1.0 : 0.0);
  f[kBrightness] = centre.mapped.mean(0);
  f[kFuture] = constant(forward ? 1.0 : 0.0);
  return torch::stack(f, 1);
}

// LearnedTrust::weigh over every pixel: its layers as matrix products.
Tensor weighAll(const LearnedTrust& trust, const Tensor& features) {
  const std::vector<int>& sizes = trust.sizes();
  // In double: no TF32 for matrix products on a GPU where it is switched on.
  const Tensor params = torch::tensor(trust.params()).to(features.device(), torch::kDouble);
  Tensor x = features.to(torch::kDouble);
  std::int64_t at = 0;
  for (std::size_t l = 1; l < sizes.size(); ++l) {
    const std::int64_t n = sizes[l - 1], m = sizes[l];
    const Tensor weights = params.slice(0, at, at + n * m).view({m, n});
    const Tensor bias = params.slice(0, at + n * m, at + n * m + m);
    x = torch::addmm(bias, x, weights.t());
    if (l + 1 < sizes.size()) x = torch::relu(x);
    at += n * m + m;
  }
  return torch::sigmoid(x.squeeze(1)).to(torch::kFloat);
}

// TemporalOptions::driftThreshold (applyDrift of temporal_filter.cpp).
void applyDrift(Contribution& k, const Tensor& own, const TemporalOptions& options, const Grid& g) {
  if (options.driftThreshold <= 0.0 || !k.used() || k.relight.defined()) return;
  const Tensor factor =
      driftFactor(k.image, own, k.weight, options.driftBox, options.driftThreshold, g);
  const Tensor drifted = (factor != 1.0f).any(0);
  if (!drifted.any().item<bool>()) return;
  k.image = k.image * factor;
  if (k.history.defined()) k.history = k.history * factor;
  k.relight = factor;
  k.drifted = drifted;
}

void applyLearnedTrust(Contribution& k, const Tensor& features, const LearnedTrust& trust) {
  const Tensor w = weighAll(trust, features);
  // NaN (a feature of a NaN render): 0.
  k.weight = torch::where(k.weight > 0, onlyWhere(w > 0, k.weight * w), k.weight);
}

// TemporalOptions::viewDependentMotion: the view-dependent share of the
// weight counts only where the surface stood still.
void applyViewDependence(Contribution& k, const Tensor& share, double pixels, const Grid& g) {
  if (!share.defined() || !k.used() || pixels <= 0.0) return;
  const Tensor s = share[0];
  k.weight = k.weight * (1.0f - s + s * stillness(k.resampling.positions, pixels, g));
}

// The noisy renders accumulated with the results' weights, at the nearest pixel.
void accumulateNoisy(const Centre& centre, const std::vector<const DeviceFrame*>& frames,
                     const std::vector<Contribution>& contributions, DeviceTemporalResult& result) {
  const Grid& g = centre.grid;
  Tensor sum = centre.frame->noisy.clone();
  Tensor weight = torch::ones({g.pixels()}, sum.options()), squares = weight.clone();
  for (std::size_t k = 0; k < contributions.size(); ++k) {
    const Contribution& c = contributions[k];
    if (!c.used()) continue;
    Tensor moved = reprojectNearest(frames[k]->noisy, c.resampling.positions, g);
    if (c.relight.defined()) moved = moved * c.relight;
    const Tensor w = onlyWhere(c.weight > 0, c.weight);
    sum = sum + w * moved;
    weight = weight + w;
    squares = squares + w * w;
  }
  result.history = sum / weight;
  result.historyFrames = (weight * weight / squares).unsqueeze(0);
  result.stats.accumulatedFrames = result.historyFrames.mean(torch::kDouble).item<double>();
}

DevicePastHistories pastHistoriesOf(const std::vector<Contribution>& contributions,
                                    const std::vector<std::size_t>& indices, const Centre& centre) {
  DevicePastHistories out;
  for (std::size_t n = 0; n < contributions.size(); ++n) {
    const Contribution& k = contributions[n];
    if (!k.history.defined() || !k.used()) continue;
    const Tensor weight = k.weight * k.historyWeight;
    if (!(weight > 0).any().item<bool>()) continue;
    out.images.push_back(k.history);
    out.weights.push_back(weight);
    out.frames.push_back(indices[n]);
  }
  if (!out.empty()) out.scale = centre.scale, out.noise = centre.noise;
  return out;
}

// The neighbours in order (the past nearest first, then the future), each
// with the chain of frames its motion is followed along; a gap ends a side.
struct Neighbour {
  const DeviceFrame* frame;
  std::size_t index;
  std::vector<const DeviceFrame*> chain;
  bool forward;
};

std::vector<Neighbour> neighboursOf(const std::vector<const DeviceFrame*>& window,
                                    std::size_t centre, int radius) {
  const DeviceFrame& current = *window[centre];
  std::vector<Neighbour> out;
  for (int side : {-1, 1}) {
    std::vector<const DeviceFrame*> chain = {&current};
    for (int k = 1; k <= radius; ++k) {
      const long index = static_cast<long>(centre) + side * k;
      if (index < 0 || index >= static_cast<long>(window.size()) || !window[index]) break;
      const DeviceFrame& frame = *window[index];
      if (!frame.hasMotion() || !current.hasMotion()) break;
      if (frame.width != current.width || frame.height != current.height ||
          frame.toNext.size(1) != current.toNext.size(1))
        throw std::invalid_argument("filterFrame: every frame needs motion of the same size");
      chain.push_back(&frame);
      out.push_back({&frame, static_cast<std::size_t>(index), chain, side > 0});
    }
  }
  return out;
}

// The per-neighbour shares of trusted pixels and the history's share, in one copy to the host.
void countTrusted(const std::vector<Contribution>& contributions, const Tensor& totalWeight,
                  TemporalStats& stats) {
  std::vector<Tensor> counts;
  for (const Contribution& k : contributions)
    counts.push_back(k.used() ? (k.weight > 0).sum().to(torch::kDouble)
                              : torch::zeros({}, totalWeight.options().dtype(torch::kDouble)));
  counts.push_back((1.0 - 1.0 / totalWeight.to(torch::kDouble)).sum());
  const Tensor host = torch::stack(counts).cpu();
  const double pixels = double(totalWeight.numel());
  for (std::size_t k = 0; k < contributions.size(); ++k)
    stats.trusted.push_back(host[k].item<double>() / pixels);
  stats.historyShare = host[contributions.size()].item<double>() / std::max(1.0, pixels);
}

// TrustSamples on the host for options.observeTrust.
void observe(const Centre& centre, const std::vector<Neighbour>& neighbours,
             const std::vector<Contribution>& contributions, const std::vector<Tensor>& features,
             const TemporalOptions& options) {
  const Grid& g = centre.grid;
  TrustSamples samples{pixelsToImage(centre.frame->denoised, g.width, g.height),
                       centre.scale.item<double>(),
                       {},
                       {},
                       {},
                       {}};
  for (std::size_t n = 0; n < contributions.size(); ++n) {
    if (!features[n].defined()) continue;
    samples.frames.push_back(neighbours[n].index);
    samples.moved.push_back(pixelsToImage(contributions[n].image, g.width, g.height));
    const Tensor f = features[n].contiguous().cpu();
    samples.features.emplace_back(f.data_ptr<float>(), f.data_ptr<float>() + f.numel());
    const Tensor w = contributions[n].weight.to(torch::kDouble).contiguous().cpu();
    samples.weights.emplace_back(w.data_ptr<double>(), w.data_ptr<double>() + w.numel());
  }
  options.observeTrust(samples);
}

std::vector<double> toDoubles(const Tensor& t) {
  const Tensor host = t.to(torch::kDouble).contiguous().cpu();
  return {host.data_ptr<double>(), host.data_ptr<double>() + host.numel()};
}

}  // namespace

torch::Tensor pixelsToDevice(const Image& image, const torch::Device& device) {
  if (image.empty()) return {};
  return imageToDevice(image, device).reshape({image.channels, -1}).contiguous();
}

Image pixelsToImage(const torch::Tensor& pixels, int width, int height) {
  return tensorToImage(pixels.reshape({1, -1, height, width}));
}

DeviceFrame toDevice(const WindowFrame& frame, const torch::Device& device) {
  DeviceFrame out;
  out.width = frame.denoised.width(), out.height = frame.denoised.height();
  Image scratch;
  auto upload = [&](const WindowImage& image) {
    return pixelsToDevice(image.floats(scratch), device);
  };
  out.denoised = upload(frame.denoised);
  out.noisy = upload(frame.noisy);
  out.history = upload(frame.history);
  out.albedo = upload(frame.guides.albedo);
  out.normal = upload(frame.guides.normal);
  out.depth = upload(frame.guides.depth);
  out.viewDependent = upload(frame.viewDependent);
  if (!frame.motion.empty()) {
    out.toPrevious = upload(frame.motion.toPrevious);
    out.toNext = upload(frame.motion.toNext);
  }
  return out;
}

motion::Resampling DeviceResampling::toHost(int width, int height) const {
  motion::Resampling out;
  out.positions = pixelsToImage(positions, width, height);
  out.trust = pixelsToImage(trust.unsqueeze(0), width, height);
  const Tensor bits = taps.contiguous().cpu();
  out.taps.assign(bits.data_ptr<std::uint8_t>(), bits.data_ptr<std::uint8_t>() + bits.numel());
  return out;
}

FilterWeights DeviceFilterWeights::toHost() const {
  FilterWeights out;
  out.centre = centre;
  out.relightBox = relightBox;
  out.relightRange = relightRange;
  out.driftBox = driftBox;
  for (const DeviceNeighbourWeights& nb : neighbours) {
    std::vector<unsigned char> drifted;
    if (nb.drifted.defined()) {
      const Tensor bytes = nb.drifted.to(torch::kUInt8).contiguous().cpu();
      drifted.assign(bytes.data_ptr<std::uint8_t>(),
                     bytes.data_ptr<std::uint8_t>() + bytes.numel());
    }
    out.neighbours.push_back({nb.frame, nb.resampling.toHost(width, height), nb.relit,
                              std::move(drifted), toDoubles(nb.weight)});
  }
  return out;
}

DeviceTemporalResult filterFrame(const std::vector<const DeviceFrame*>& window, std::size_t centre,
                                 const TemporalOptions& options) {
  if (centre >= window.size() || !window[centre])
    throw std::invalid_argument("filterFrame: the centre frame is missing");
  torch::NoGradGuard noGrad;
  const DeviceFrame& current = *window[centre];
  if (current.viewDependent.defined() &&
      current.viewDependent.numel() != std::int64_t(current.width) * current.height)
    throw std::invalid_argument("filterFrame: the view-dependent share differs in size");
  const std::vector<Neighbour> neighbours = neighboursOf(window, centre, options.radius);
  const Centre c = centreOf(current, options.trust);
  std::vector<Contribution> contributions;
  for (const Neighbour& nb : neighbours)
    contributions.push_back(contributionOf(c, *nb.frame, nb.chain, nb.forward, options));
  // The learned trust's view of each neighbour, where it or an observer needs it.
  std::vector<Tensor> features(contributions.size());
  if (options.learnedTrust || options.observeTrust) {
    const Tensor meanMapped = guideMean(c, contributions);
    for (std::size_t n = 0; n < contributions.size(); ++n) {
      if (!contributions[n].used()) continue;
      const long distance = std::labs(long(neighbours[n].index) - long(centre));
      features[n] =
          trustFeatures(c, contributions[n], meanMapped, int(distance), neighbours[n].forward);
    }
  }
  const Tensor ownMean = weightedMean(current.denoised, usedOf(contributions)).first;
  const Tensor referenceMapped =
      tonemapped((1.0f - float(options.colourReference)) * current.denoised +
                     float(options.colourReference) * ownMean,
                 c.scale);
  for (std::size_t n = 0; n < contributions.size(); ++n) {
    applyColourTest(contributions[n], referenceMapped, c, options);
    if (options.learnedTrust && features[n].defined())
      applyLearnedTrust(contributions[n], features[n], *options.learnedTrust);
    applyViewDependence(contributions[n], current.viewDependent, options.viewDependentMotion,
                        c.grid);
  }
  if (options.observeTrust) observe(c, neighbours, contributions, features, options);
  for (Contribution& k : contributions) applyDrift(k, current.denoised, options, c.grid);

  DeviceTemporalResult result;
  result.width = current.width, result.height = current.height;
  Tensor totalWeight;
  std::tie(result.color, totalWeight) = weightedMean(current.denoised, usedOf(contributions));
  result.stats.neighbours = static_cast<int>(neighbours.size());
  for (const Contribution& k : contributions) {
    result.stats.repeatedNoise += k.verdict == Contribution::Verdict::RepeatedNoise;
    result.stats.changedLight += k.verdict == Contribution::Verdict::ChangedLight;
    result.stats.relit += k.verdict == Contribution::Verdict::Relit;
    result.stats.drifted += k.drifted.defined();
  }
  countTrusted(contributions, totalWeight, result.stats);
  if (options.accumulatedShare > 0.0) {
    std::vector<const DeviceFrame*> frames;
    for (const Neighbour& nb : neighbours) frames.push_back(nb.frame);
    accumulateNoisy(c, frames, contributions, result);
    std::vector<std::size_t> indices;
    for (const Neighbour& nb : neighbours) indices.push_back(nb.index);
    result.pastHistories = pastHistoriesOf(contributions, indices, c);
  }
  DeviceFilterWeights& weights = result.weights;
  weights.centre = centre;
  weights.relightBox = options.relightBox;
  weights.relightRange = options.relightRange;
  weights.driftBox = options.driftBox;
  weights.width = current.width, weights.height = current.height;
  for (std::size_t k = 0; k < contributions.size(); ++k) {
    Contribution& n = contributions[k];
    if (!n.used()) continue;
    weights.neighbours.push_back({neighbours[k].index, std::move(n.resampling),
                                  n.relight.defined() && !n.drifted.defined(), n.drifted,
                                  std::move(n.weight)});
  }
  return result;
}

torch::Tensor filterWith(const DeviceFilterWeights& weights,
                         const std::vector<const torch::Tensor*>& images, double stillPixels) {
  if (weights.centre >= images.size() || !images[weights.centre])
    throw std::invalid_argument("filterWith: the centre frame's image is missing");
  torch::NoGradGuard noGrad;
  const Tensor& own = *images[weights.centre];
  const Grid g = gridOf(weights.width, weights.height, own.options().dtype(torch::kFloat));
  std::vector<Tensor> moved, used;
  for (const DeviceNeighbourWeights& nb : weights.neighbours) {
    const Tensor* image = nb.frame < images.size() ? images[nb.frame] : nullptr;
    if (!image || !image->defined() || image->sizes() != own.sizes()) continue;
    Tensor in = resample(nb.resampling, *image, g);
    Tensor weight = nb.weight;
    if (nb.relit) {  // this image's own factor
      const Tensor factor =
          relightFactor(in, own, nb.resampling.trust, weights.relightBox, weights.relightRange, g);
      in = in * factor;
      weight = relitWeight(weight, factor);
    } else if (nb.drifted.defined()) {
      in = in * driftFactor(in, own, nb.weight, weights.driftBox, 0.0, g, nb.drifted);
    }
    moved.push_back(in);
    used.push_back(stillPixels > 0.0 ? weight * stillness(nb.resampling.positions, stillPixels, g)
                                     : weight);
  }
  std::vector<Weighted> others;
  for (std::size_t k = 0; k < moved.size(); ++k) others.push_back({&moved[k], &used[k]});
  return weightedMean(own, others).first;
}

namespace {

// Per past history, its weight in historyMean: where it differs from the
// frame's own by less than the noise its accumulated render still had
// (historyTrust of temporal_filter.cpp).
std::vector<Tensor> historyTrust(const Tensor& own, const DeviceTemporalResult& result,
                                 const TemporalOptions& options) {
  const DevicePastHistories& past = result.pastHistories;
  for (const Tensor& image : past.images)
    if (image.sizes() != own.sizes())
      throw std::invalid_argument("historyMean: the images differ in shape");
  const Tensor ownMapped = tonemapped(own, past.scale);
  const Tensor error = past.noise * torch::sqrt(2.0f / result.historyFrames[0]);
  std::vector<Tensor> weights;
  for (std::size_t k = 0; k < past.images.size(); ++k) {
    const Tensor d = absoluteDifference(tonemapped(past.images[k], past.scale), ownMapped);
    weights.push_back(
        past.weights[k] *
        ((options.lightHigh - d / error) / (options.lightHigh - options.lightLow)).clamp(0.0, 1.0));
  }
  return weights;
}

}  // namespace

FilterWeights historyWeights(const torch::Tensor& own, const DeviceTemporalResult& result,
                             const FilterWeights& taps, const TemporalOptions& options) {
  if (result.pastHistories.empty()) return FilterWeights();
  torch::NoGradGuard noGrad;
  std::vector<std::vector<double>> weights;
  for (const Tensor& w : historyTrust(own, result, options)) weights.push_back(toDoubles(w));
  return pastWeights(taps, result.pastHistories.frames, std::move(weights));
}

torch::Tensor historyMean(const torch::Tensor& own, const DeviceTemporalResult& result,
                          const TemporalOptions& options) {
  const DevicePastHistories& past = result.pastHistories;
  if (past.empty()) return own;
  torch::NoGradGuard noGrad;
  const std::vector<Tensor> weights = historyTrust(own, result, options);
  std::vector<Weighted> others;
  for (std::size_t k = 0; k < weights.size(); ++k) others.push_back({&past.images[k], &weights[k]});
  return weightedMean(own, others).first;
}

torch::Tensor blendWithHistory(const torch::Tensor& filtered, const torch::Tensor& accumulated,
                               double share) {
  if (filtered.sizes() != accumulated.sizes())
    throw std::invalid_argument("blendWithHistory: the images differ in shape");
  return (1.0f - float(share)) * filtered + float(share) * accumulated;
}

TemporalResult toHost(const DeviceTemporalResult& result, bool withWeights) {
  const int w = result.width, h = result.height;
  TemporalResult out;
  out.color = pixelsToImage(result.color, w, h);
  if (withWeights) out.weights = result.weights.toHost();
  if (result.history.defined()) {
    out.history = pixelsToImage(result.history, w, h);
    out.historyFrames = pixelsToImage(result.historyFrames, w, h);
  }
  const DevicePastHistories& past = result.pastHistories;
  for (std::size_t k = 0; k < past.images.size(); ++k) {
    out.pastHistories.images.push_back(pixelsToImage(past.images[k], w, h));
    out.pastHistories.weights.push_back(toDoubles(past.weights[k]));
  }
  out.pastHistories.frames = past.frames;
  if (!past.empty()) {
    out.pastHistories.scale = past.scale.item<double>();
    const Tensor noise = past.noise.contiguous().cpu();
    out.pastHistories.noise.assign(noise.data_ptr<float>(),
                                   noise.data_ptr<float>() + noise.numel());
  }
  out.stats = result.stats;
  return out;
}

}  // namespace dn::temporal
