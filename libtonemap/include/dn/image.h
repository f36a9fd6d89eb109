// A plain float image: the currency between libtonemap, libmetrics and the
// buffer I/O. Pixels are interleaved (x fastest, then channel-major per pixel).
#pragma once

#include <cstddef>
#include <vector>

namespace dn {

struct Image {
  int width = 0;
  int height = 0;
  int channels = 0;
  std::vector<float> pixels;

  Image() = default;
  Image(int w, int h, int c, float fill = 0.0f)
      : width(w), height(h), channels(c), pixels(static_cast<std::size_t>(w) * h * c, fill) {}

  std::size_t pixelCount() const { return static_cast<std::size_t>(width) * height; }
  std::size_t size() const { return pixels.size(); }
  bool empty() const { return pixels.empty(); }
  bool sameShape(const Image& o) const {
    return width == o.width && height == o.height && channels == o.channels;
  }

  float& at(int x, int y, int c) { return pixels[index(x, y, c)]; }
  float at(int x, int y, int c) const { return pixels[index(x, y, c)]; }
  float* pixel(int x, int y) { return &pixels[index(x, y, 0)]; }
  const float* pixel(int x, int y) const { return &pixels[index(x, y, 0)]; }

 private:
  std::size_t index(int x, int y, int c) const {
    return (static_cast<std::size_t>(y) * width + x) * channels + c;
  }
};

}  // namespace dn
