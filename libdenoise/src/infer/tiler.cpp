#include "dn/infer/tiler.h"

#include <algorithm>
#include <cmath>

namespace dn {

namespace {

// Tile starts along one axis: regular steps, the last tile flush with the end.
std::vector<int64_t> starts(int64_t size, int64_t tile, int64_t overlap) {
  if (tile >= size) return {0};
  std::vector<int64_t> out;
  const int64_t stride = tile - overlap;
  for (int64_t s = 0;; s += stride) {
    if (s + tile >= size) {
      out.push_back(size - tile);
      break;
    }
    out.push_back(s);
  }
  return out;
}

// Blend weight along one axis of a tile: 0 within `margin` of an inner edge,
// then a linear ramp to 1 across the rest of the overlap; 1 at frame edges.
torch::Tensor ramp(int64_t start, int64_t length, int64_t size, int64_t overlap, int64_t margin) {
  auto w = torch::ones({length});
  auto a = w.accessor<float, 1>();
  const double span = std::max<int64_t>(1, overlap - 2 * margin);
  for (int64_t i = 0; i < length; ++i) {
    double v = 1.0;
    if (start > 0) v = std::min(v, (i + 0.5 - margin) / span);
    if (start + length < size) v = std::min(v, (length - i - 0.5 - margin) / span);
    a[i] = static_cast<float>(std::clamp(v, 0.0, 1.0));
  }
  return w;
}

}  // namespace

Tiler::Tiler(int64_t height, int64_t width, int64_t tile, int64_t overlap)
    : Tiler(height, width, tile, tile, overlap) {}

Tiler::Tiler(int64_t height, int64_t width, int64_t tileHeight, int64_t tileWidth, int64_t overlap)
    : height_(height), width_(width) {
  const int64_t th = tileHeight > 0 ? std::min(tileHeight, height) : height;
  const int64_t tw = tileWidth > 0 ? std::min(tileWidth, width) : width;
  overlap_ = std::clamp<int64_t>(overlap, 0, std::min(th, tw) / 2);
  margin_ = overlap_ / 4;
  for (int64_t y : starts(height, th, overlap_))
    for (int64_t x : starts(width, tw, overlap_)) tiles_.push_back({y, x, th, tw});
}

torch::Tensor Tiler::weights(const TileRect& r) const {
  auto wy = ramp(r.y0, r.height, height_, overlap_, margin_);
  auto wx = ramp(r.x0, r.width, width_, overlap_, margin_);
  return (wy.unsqueeze(1) * wx.unsqueeze(0)).view({1, 1, r.height, r.width});
}

torch::Tensor crop(const torch::Tensor& tensor, const TileRect& r) {
  return tensor.narrow(2, r.y0, r.height).narrow(3, r.x0, r.width);
}

torch::Tensor Tiler::apply(
    const std::vector<torch::Tensor>& inputs,
    const std::function<torch::Tensor(const std::vector<torch::Tensor>&)>& fn) const {
  return apply([&](const TileRect& r) {
    std::vector<torch::Tensor> slices;
    for (const auto& in : inputs) slices.push_back(in.defined() ? crop(in, r) : in);
    return fn(slices);
  });
}

torch::Tensor Tiler::apply(const std::function<torch::Tensor(const TileRect&)>& fn) const {
  if (tiles_.size() == 1) return fn(tiles_.front());
  torch::Tensor sum, weightSum;
  for (const auto& r : tiles_) {
    torch::Tensor out = fn(r);
    if (!sum.defined()) {
      sum = torch::zeros({out.size(0), out.size(1), height_, width_}, out.options());
      weightSum = torch::zeros({1, 1, height_, width_}, out.options());
    }
    torch::Tensor w = weights(r).to(out.options());
    crop(sum, r).add_(out * w);
    crop(weightSum, r).add_(w);
  }
  return sum.div_(weightSum.clamp_min_(1e-12));  // in place: one full-frame output, not two
}

int64_t tiledPixels(const Tiler& tiler) {
  int64_t pixels = 0;
  for (const auto& r : tiler.tiles()) pixels += r.height * r.width;
  return pixels;
}

int64_t tileSizeForMemory(double bytes, double bytesPerPixel, int64_t multiple) {
  int64_t side = static_cast<int64_t>(std::sqrt(std::max(0.0, bytes / bytesPerPixel)));
  return std::max(multiple, side / multiple * multiple);
}

}  // namespace dn
