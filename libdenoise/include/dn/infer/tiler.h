// Splits a frame into overlapping tiles so large frames fit a memory bound, and
// blends per-tile outputs back seamlessly. Used per diffusion step: the sampler
// state and its noise stay full-frame, only the network runs on tiles, so a
// tiled run sees the same noise field as an untiled one.
#pragma once

#include <cstdint>
#include <functional>
#include <vector>

#include <torch/torch.h>

namespace dn {

struct TileRect {
  int64_t y0, x0, height, width;
};

// The rectangle's pixels of an (N,C,H,W) tensor (a view, no copy).
torch::Tensor crop(const torch::Tensor& tensor, const TileRect& r);

class Tiler {
 public:
  // tile <= 0 or >= the frame: one tile. The overlap is clamped to tile / 2.
  Tiler(int64_t height, int64_t width, int64_t tile, int64_t overlap);
  // Tiles of tileHeight x tileWidth (each <= 0: the frame's size).
  Tiler(int64_t height, int64_t width, int64_t tileHeight, int64_t tileWidth, int64_t overlap);

  const std::vector<TileRect>& tiles() const { return tiles_; }
  // Pixels this far from an inner tile edge get zero weight, so any operator
  // whose receptive field radius is at most this gives exactly the untiled result.
  int64_t exactMargin() const { return margin_; }

  // fn maps (N,*,h,w) slices of `inputs` to an (N,C,h,w) output; returns the
  // blended (N,C,H,W) full-frame output.
  torch::Tensor apply(
      const std::vector<torch::Tensor>& inputs,
      const std::function<torch::Tensor(const std::vector<torch::Tensor>&)>& fn) const;
  // The same with fn building each tile's inputs itself from its rectangle, so
  // inputs that are cheap to derive per pixel need not exist at full-frame size.
  torch::Tensor apply(const std::function<torch::Tensor(const TileRect&)>& fn) const;

 private:
  torch::Tensor weights(const TileRect& r) const;  // (1,1,h,w)

  int64_t height_, width_, overlap_, margin_;
  std::vector<TileRect> tiles_;
};

// Tile size whose network activations stay under `bytes`, given the measured
// or estimated bytes per pixel of one forward pass; a multiple of `multiple`.
int64_t tileSizeForMemory(double bytes, double bytesPerPixel, int64_t multiple);

// Pixels the networks process over all tiles of a layout (overlaps counted
// every time they are run).
int64_t tiledPixels(const Tiler& tiler);

}  // namespace dn
