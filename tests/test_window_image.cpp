// Half floats in the temporal window: the conversions against IEEE binary16
// (every half exactly, floats rounded to the nearest with ties to even, the
// processor's F16C path the same bits as the portable one), packing that keeps
// a half-float file's values bit for bit, an image of one value as that value,
// the rounding of packed results within half's precision at any exposure, and
// rows unpacked for threads.
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <random>
#include <stdexcept>
#include <vector>

#include <doctest/doctest.h>

#include "dn/temporal/window_image.h"

using namespace dn;
using namespace dn::temporal;

namespace {

// A half's value from its fields, in double: the reference the conversions meet.
double halfValue(std::uint16_t h) {
  const int exponent = (h >> 10) & 0x1f, fraction = h & 0x3ff;
  const double sign = (h & 0x8000) ? -1.0 : 1.0;
  if (exponent == 0x1f)
    return fraction ? std::numeric_limits<double>::quiet_NaN()
                    : sign * std::numeric_limits<double>::infinity();
  if (exponent == 0) return sign * std::ldexp(fraction, -24);
  return sign * std::ldexp(1024 + fraction, exponent - 25);
}

// The nearest half to `v` by search over the finite halves of its sign, ties
// to the even fraction; infinity beyond 65520 (half way past the largest).
std::uint16_t nearestHalf(float v) {
  const std::uint16_t sign = std::signbit(v) ? 0x8000 : 0;
  const double a = std::abs(double(v));
  if (a >= 65520.0) return sign | 0x7c00;
  std::uint16_t best = 0;
  double bestError = a;
  for (std::uint16_t h = 1; h < 0x7c00; ++h) {
    const double error = std::abs(halfValue(h) - a);
    if (error < bestError || (error == bestError && (h & 1) == 0 && (best & 1) == 1))
      best = h, bestError = error;
  }
  return sign | best;
}

std::vector<float> halvesToFloats(const std::vector<std::uint16_t>& h) {
  std::vector<float> out(h.size());
  toFloats(h.data(), h.size(), 1.0f, out.data());
  return out;
}

}  // namespace

TEST_CASE("every half converts to its exact value and back, in bulk and one at a time") {
  std::vector<std::uint16_t> all(1 << 16);
  for (std::size_t i = 0; i < all.size(); ++i) all[i] = static_cast<std::uint16_t>(i);
  const std::vector<float> floats = halvesToFloats(all);
  std::vector<std::uint16_t> back(all.size());
  toHalves(floats.data(), floats.size(), 1.0f, back.data());
  for (std::size_t i = 0; i < all.size(); ++i) {
    const double expected = halfValue(all[i]);
    if (std::isnan(expected)) {
      CHECK(std::isnan(floats[i]));
      CHECK(std::isnan(floatOf(all[i])));
      continue;
    }
    REQUIRE(double(floats[i]) == expected);
    REQUIRE(floatOf(all[i]) == floats[i]);
    REQUIRE(back[i] == all[i]);
    REQUIRE(halfOf(floats[i]) == all[i]);
  }
}

TEST_CASE("floats round to the nearest half, ties to even, the same bits in bulk") {
  std::vector<float> values = {0.0f,     -0.0f,    1.0f,   65504.0f,   65519.99f,
                               65520.0f, 1e9f,     -1e9f,  6.1035e-5f, 5.96e-8f,
                               2.98e-8f, 2.99e-8f, 1e-30f, -3.3333f,   0.1f};
  // Ties: half way between neighbouring halves, in the normal and subnormal ranges.
  for (std::uint16_t h : {0x3c00, 0x3c01, 0x0001, 0x0002, 0x03ff, 0x7bfe})
    values.push_back(float((halfValue(h) + halfValue(h + 1)) / 2));
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> exponent(-26.0f, 17.0f);
  for (int i = 0; i < 3000; ++i)
    values.push_back((i % 2 ? -1.0f : 1.0f) * std::exp2(exponent(rng)));
  std::vector<std::uint16_t> bulk(values.size());
  toHalves(values.data(), values.size(), 1.0f, bulk.data());
  for (std::size_t i = 0; i < values.size(); ++i) {
    CAPTURE(values[i]);
    const std::uint16_t expected = nearestHalf(values[i]);
    CHECK(halfOf(values[i]) == expected);
    CHECK(bulk[i] == expected);
  }
}

TEST_CASE("packing keeps a half-float file's values bit for bit, and others in floats") {
  Image fromHalfFile(9, 5, 3);
  for (std::size_t i = 0; i < fromHalfFile.pixels.size(); ++i)
    fromHalfFile.pixels[i] = floatOf(static_cast<std::uint16_t>(0x2000 + 97 * i));
  WindowImage exact(fromHalfFile);
  exact.packIfExact();
  CHECK(exact.packed());
  CHECK(exact.bytes() == fromHalfFile.pixels.size() * 2);
  CHECK(exact.toImage().pixels == fromHalfFile.pixels);
  CHECK(exact.width() == 9);
  CHECK(exact.height() == 5);
  CHECK(exact.channels() == 3);
  CHECK_THROWS_AS(exact.floats(), std::logic_error);

  // One value no half holds, anywhere: in a block of eight (the F16C path),
  // at its edges, or in the tail past the last whole block (135 values).
  for (std::size_t at : {std::size_t(0), std::size_t(7), std::size_t(8), std::size_t(17),
                         std::size_t(127), std::size_t(128), std::size_t(134)}) {
    for (float odd : {0.1f, std::numeric_limits<float>::quiet_NaN(), 1e-9f, 70000.0f}) {
      CAPTURE(at);
      CAPTURE(odd);
      Image rendered = fromHalfFile;
      rendered.pixels[at] = odd;
      WindowImage inFloats(rendered);
      inFloats.packIfExact();
      CHECK_FALSE(inFloats.packed());
      CHECK(std::memcmp(inFloats.floats().pixels.data(), rendered.pixels.data(),
                        rendered.pixels.size() * sizeof(float)) == 0);
    }
  }
  // Signed zeros and infinities are halves: packed, and back with their signs.
  Image signs = fromHalfFile;
  signs.pixels[3] = -0.0f, signs.pixels[40] = std::numeric_limits<float>::infinity();
  signs.pixels[133] = -std::numeric_limits<float>::infinity();
  WindowImage withSigns(signs);
  withSigns.packIfExact();
  CHECK(withSigns.packed());
  const Image back = withSigns.toImage();
  CHECK(std::memcmp(back.pixels.data(), signs.pixels.data(), signs.pixels.size() * 4) == 0);
}

TEST_CASE("rows in floats are the image's rows, packed or not, and only those rows are written") {
  Image image(6, 5, 3);
  for (std::size_t i = 0; i < image.pixels.size(); ++i) image.pixels[i] = 0.37f * i - 3.0f;
  WindowImage rounded(image), exact(image), constant(Image(6, 5, 3, 2.5f)), asGiven(image);
  rounded.pack();
  exact.packIfExact();  // 0.37 i - 3 is no half for most i: held in floats
  constant.pack();
  CHECK(rounded.packed());
  CHECK_FALSE(exact.packed());
  CHECK(constant.packed());
  for (const WindowImage* held : {&rounded, &exact, &constant, &asGiven}) {
    const Image whole = held->toImage();
    Image rows(6, 5, 3, -7.0f);
    held->floatsRows(rows, 1, 3);
    for (int y = 0; y < 5; ++y)
      for (int x = 0; x < 6; ++x)
        for (int c = 0; c < 3; ++c)
          CHECK(rows.at(x, y, c) == (y >= 1 && y < 3 ? whole.at(x, y, c) : -7.0f));
  }
  Image wrongShape(5, 6, 3);
  CHECK_THROWS_AS(rounded.floatsRows(wrongShape, 0, 1), std::invalid_argument);
  Image movedOut(6, 5, 3);
  const std::vector<float> taken = std::move(movedOut.pixels);
  CHECK_THROWS_AS(rounded.floatsRows(movedOut, 0, 1), std::invalid_argument);
}

TEST_CASE("an image unpacked into a scratch reuses it where it fits, and remakes it where not") {
  Image image(6, 5, 3);
  for (std::size_t i = 0; i < image.pixels.size(); ++i) image.pixels[i] = 0.37f * i - 3.0f;
  WindowImage rounded(image);
  rounded.pack();
  const Image whole = rounded.toImage();
  Image fits(6, 5, 3, -7.0f), other(2, 2, 3), movedOut(6, 5, 3);
  const float* kept = fits.pixels.data();
  CHECK(rounded.floats(fits).pixels == whole.pixels);
  CHECK(fits.pixels.data() == kept);
  CHECK(rounded.floats(other).pixels == whole.pixels);
  const std::vector<float> taken = std::move(movedOut.pixels);
  CHECK(rounded.floats(movedOut).pixels == whole.pixels);
  // Held in floats: the image itself, the scratch untouched.
  const WindowImage asGiven(image);
  Image untouched(1, 1, 3, -7.0f);
  CHECK(&asGiven.floats(untouched) != &untouched);
  CHECK(untouched.pixels == std::vector<float>(3, -7.0f));
}

TEST_CASE("an image of one value is held as that value, bit for bit, whatever the value") {
  for (const float value : {1.0f, 0.1f, -0.0f, std::numeric_limits<float>::infinity()}) {
    CAPTURE(value);
    const Image ones(7, 4, 1, value);
    WindowImage exact(ones), rounded(ones);
    exact.packIfExact();
    rounded.pack();
    for (const WindowImage* held : {&exact, &rounded}) {
      CHECK(held->packed());
      CHECK(held->bytes() == 0);
      CHECK((held->width() == 7 && held->height() == 4 && held->channels() == 1));
      const Image back = held->toImage();
      REQUIRE(back.sameShape(ones));
      for (float v : back.pixels) CHECK(std::signbit(v) == std::signbit(value));
      CHECK(back.pixels == ones.pixels);
    }
  }
  // One value's bits differ: -0 is not 0.
  Image almost(3, 3, 1, 0.0f);
  almost.pixels[4] = -0.0f;
  WindowImage held(almost);
  held.packIfExact();
  CHECK(held.bytes() == almost.pixels.size() * 2);
  CHECK(std::signbit(held.toImage().pixels[4]));
}

TEST_CASE("a packed result keeps 11 significant bits, from a dark frame to a visible sun") {
  for (float exposure : {1e-6f, 1.0f, 3e6f}) {
    CAPTURE(exposure);
    Image result(16, 16, 3);
    std::mt19937 rng(11);
    std::uniform_real_distribution<float> stops(-12.0f, 0.0f);
    for (float& v : result.pixels) v = exposure * std::exp2(stops(rng));
    WindowImage packed(result);
    packed.pack();
    REQUIRE(packed.packed());
    Image scratch;
    const Image& back = packed.floats(scratch);
    for (std::size_t i = 0; i < result.pixels.size(); ++i)
      REQUIRE(std::abs(back.pixels[i] - result.pixels[i]) <= result.pixels[i] * 0x1p-11f);
  }
  Image withInfinity(4, 4, 1, 1.0f);
  withInfinity.pixels[3] = std::numeric_limits<float>::infinity();
  WindowImage kept(withInfinity);
  kept.pack();
  CHECK_FALSE(kept.packed());
  WindowImage empty;
  empty.pack();
  CHECK(empty.empty());
}
