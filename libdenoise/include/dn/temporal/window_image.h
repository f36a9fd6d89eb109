// An image of a sequence's window, in floats, packed in half floats (IEEE
// binary16), or as the one value of all its pixels (an alpha of ones). The
// window holds nine frames; packed, a 1080p frame's noisy render, albedo,
// result and history take half the memory.
#pragma once

#include <cstdint>
#include <vector>

#include "dn/image.h"

namespace dn::temporal {

class WindowImage {
 public:
  WindowImage() = default;
  WindowImage(Image image) : floats_(std::move(image)) {}  // held in floats, as given

  // Packs where that changes no value: an image of one value into it, else
  // into half floats where each value is one (a half-float file's render and
  // guides, so the frame's buffers come back bit for bit); else keeps the floats.
  void packIfExact();
  // The same, and else packs into half floats rounded to the nearest, after a
  // power-of-two scale that brings the largest magnitude to the top of half's
  // range: 11 significant bits for every value down to 2^-28 of the largest.
  // Keeps the floats where a value is not finite.
  void pack();

  bool packed() const { return !halves_.empty() || constant_; }
  bool empty() const { return floats_.empty() && !packed(); }
  int width() const { return floats_.width; }
  int height() const { return floats_.height; }
  int channels() const { return floats_.channels; }
  std::size_t pixelCount() const { return floats_.pixelCount(); }
  bool sameShape(const Image& image) const { return floats_.sameShape(image); }
  bool sameShape(const WindowImage& image) const { return floats_.sameShape(image.floats_); }
  std::size_t bytes() const;

  // The image in floats: itself where held so, else unpacked into `scratch`.
  const Image& floats(Image& scratch) const;
  Image toImage() const;
  // Rows [rowBegin, rowEnd) of the image in floats into the same rows of
  // `out` (of the image's shape): for callers that split the rows among threads.
  void floatsRows(Image& out, int rowBegin, int rowEnd) const;
  // The image itself, to build a frame with; throws std::logic_error where packed.
  Image& floats();
  const Image& floats() const;

 private:
  // Whether `image` has this one's shape and its pixels (not moved out).
  bool holds(const Image& image) const;

  Image floats_;                       // the image; packed, its shape with no pixels
  std::vector<std::uint16_t> halves_;  // packed: the values times 2^exponent_
  int exponent_ = 0;
  bool constant_ = false;  // packed as the value of every pixel, `value_`
  float value_ = 0.0f;
  // Packs into `value_` where every value has the same bits.
  bool packIfConstant();
};

// IEEE binary16 conversions, on F16C where the processor has it (the same
// bits either way): round to nearest, ties to even.
std::uint16_t halfOf(float value);
float floatOf(std::uint16_t half);
void toHalves(const float* in, std::size_t count, float scale, std::uint16_t* out);
void toFloats(const std::uint16_t* in, std::size_t count, float scale, float* out);

}  // namespace dn::temporal
