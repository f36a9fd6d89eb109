#include "dn/temporal/window_image.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <stdexcept>

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#include <immintrin.h>
#define DN_F16C 1
#endif

namespace dn::temporal {
namespace {

std::uint32_t bitsOf(float value) {
  std::uint32_t bits;
  std::memcpy(&bits, &value, sizeof bits);
  return bits;
}

float fromBits(std::uint32_t bits) {
  float value;
  std::memcpy(&value, &bits, sizeof value);
  return value;
}

#ifdef DN_F16C
bool hasF16c() {
  static const bool has = __builtin_cpu_supports("f16c") && __builtin_cpu_supports("avx");
  return has;
}

__attribute__((target("avx,f16c"))) std::size_t toHalvesF16c(const float* in, std::size_t count,
                                                             float scale, std::uint16_t* out) {
  const __m256 s = _mm256_set1_ps(scale);
  std::size_t i = 0;
  for (; i + 8 <= count; i += 8) {
    const __m256 v = _mm256_mul_ps(_mm256_loadu_ps(in + i), s);
    _mm_storeu_si128(reinterpret_cast<__m128i*>(out + i),
                     _mm256_cvtps_ph(v, _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC));
  }
  return i;
}

__attribute__((target("avx,f16c"))) std::size_t toFloatsF16c(const std::uint16_t* in,
                                                             std::size_t count, float scale,
                                                             float* out) {
  const __m256 s = _mm256_set1_ps(scale);
  std::size_t i = 0;
  for (; i + 8 <= count; i += 8) {
    const __m128i h = _mm_loadu_si128(reinterpret_cast<const __m128i*>(in + i));
    _mm256_storeu_ps(out + i, _mm256_mul_ps(_mm256_cvtph_ps(h), s));
  }
  return i;
}

// toHalvesWhileExact's blocks of 8: stops at the first block holding a value
// that does not come back (NaN never does), and returns where it starts.
__attribute__((target("avx,f16c"))) std::size_t toHalvesWhileExactF16c(const float* in,
                                                                       std::size_t count,
                                                                       std::uint16_t* out) {
  std::size_t i = 0;
  for (; i + 8 <= count; i += 8) {
    const __m256 v = _mm256_loadu_ps(in + i);
    const __m128i h = _mm256_cvtps_ph(v, _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC);
    if (_mm256_movemask_ps(_mm256_cmp_ps(_mm256_cvtph_ps(h), v, _CMP_NEQ_UQ))) break;
    _mm_storeu_si128(reinterpret_cast<__m128i*>(out + i), h);
  }
  return i;
}
#endif

// Converts in[0, count) into half floats while each converts back to its
// value: how many did before the first that does not (count where all do).
std::size_t toHalvesWhileExact(const float* in, std::size_t count, std::uint16_t* out) {
  std::size_t i = 0;
#ifdef DN_F16C
  if (hasF16c()) i = toHalvesWhileExactF16c(in, count, out);
#endif
  for (; i < count; ++i) {
    out[i] = halfOf(in[i]);
    if (floatOf(out[i]) != in[i]) return i;
  }
  return count;
}

// The scale exponent that brings the largest magnitude below 2^15.
int exponentFor(const std::vector<float>& values) {
  float largest = 0.0f;
  for (float v : values) largest = std::max(largest, std::abs(v));
  if (largest == 0.0f) return 0;
  return std::clamp(15 - (std::ilogb(largest) + 1), -40, 40);
}

}  // namespace

// Round to nearest even by float addition (the subnormal range) or by a
// bias on the bits (the normal range), as IEEE 754 rounds.
std::uint16_t halfOf(float value) {
  std::uint32_t bits = bitsOf(value);
  const std::uint32_t sign = (bits >> 16) & 0x8000u;
  bits &= 0x7fffffffu;
  std::uint32_t half;
  if (bits >= 0x47800000u) {  // 2^16 and above, infinity or NaN
    half = bits > 0x7f800000u ? 0x7e00u : 0x7c00u;
  } else if (bits < 0x38800000u) {  // below 2^-14: a subnormal half or zero
    half = bitsOf(fromBits(bits) + 0.5f) - bitsOf(0.5f);
  } else {
    const std::uint32_t odd = (bits >> 13) & 1u;
    bits += (std::uint32_t(15 - 127) << 23) + 0xfffu + odd;
    half = bits >> 13;  // a carry past 65504 gives infinity
  }
  return static_cast<std::uint16_t>(half | sign);
}

float floatOf(std::uint16_t half) {
  const std::uint32_t exponent = half & 0x7c00u;
  std::uint32_t bits = std::uint32_t(half & 0x7fffu) << 13;
  if (exponent == 0x7c00u) {
    bits |= 0x7f800000u;  // infinity or NaN
  } else if (exponent == 0) {
    bits = bitsOf(fromBits(bits + (113u << 23)) - fromBits(113u << 23));  // zero or subnormal
  } else {
    bits += std::uint32_t(127 - 15) << 23;
  }
  return fromBits(bits | (std::uint32_t(half & 0x8000u) << 16));
}

void toHalves(const float* in, std::size_t count, float scale, std::uint16_t* out) {
  std::size_t i = 0;
#ifdef DN_F16C
  if (hasF16c()) i = toHalvesF16c(in, count, scale, out);
#endif
  for (; i < count; ++i) out[i] = halfOf(in[i] * scale);
}

void toFloats(const std::uint16_t* in, std::size_t count, float scale, float* out) {
  std::size_t i = 0;
#ifdef DN_F16C
  if (hasF16c()) i = toFloatsF16c(in, count, scale, out);
#endif
  for (; i < count; ++i) out[i] = floatOf(in[i]) * scale;
}

bool WindowImage::packIfConstant() {
  const std::vector<float>& v = floats_.pixels;
  const std::uint32_t first = bitsOf(v.front());
  if (!std::all_of(v.begin(), v.end(), [&](float x) { return bitsOf(x) == first; })) return false;
  constant_ = true;
  value_ = v.front();
  floats_.pixels = std::vector<float>();
  return true;
}

void WindowImage::packIfExact() {
  if (packed() || floats_.empty() || packIfConstant()) return;
  std::vector<std::uint16_t> halves(floats_.pixels.size());
  if (toHalvesWhileExact(floats_.pixels.data(), halves.size(), halves.data()) != halves.size())
    return;
  halves_ = std::move(halves);
  exponent_ = 0;
  floats_.pixels = std::vector<float>();
}

void WindowImage::pack() {
  if (packed() || floats_.empty() || packIfConstant()) return;
  if (!std::all_of(floats_.pixels.begin(), floats_.pixels.end(),
                   [](float v) { return std::isfinite(v); }))
    return;
  exponent_ = exponentFor(floats_.pixels);
  halves_.resize(floats_.pixels.size());
  toHalves(floats_.pixels.data(), halves_.size(), std::ldexp(1.0f, exponent_), halves_.data());
  floats_.pixels = std::vector<float>();
}

std::size_t WindowImage::bytes() const {
  return halves_.size() * sizeof(std::uint16_t) + floats_.pixels.size() * sizeof(float);
}

bool WindowImage::holds(const Image& image) const {
  return image.sameShape(floats_) && image.size() == floats_.pixelCount() * floats_.channels;
}

const Image& WindowImage::floats(Image& scratch) const {
  if (!packed()) return floats_;
  if (!holds(scratch)) scratch = Image(floats_.width, floats_.height, floats_.channels);
  floatsRows(scratch, 0, floats_.height);
  return scratch;
}

void WindowImage::floatsRows(Image& out, int rowBegin, int rowEnd) const {
  if (!holds(out)) throw std::invalid_argument("WindowImage: rows into another shape");
  const std::size_t row = static_cast<std::size_t>(out.width) * out.channels;
  const std::size_t begin = rowBegin * row, end = rowEnd * row;
  float* to = out.pixels.data() + begin;
  if (!packed())
    std::copy(floats_.pixels.begin() + begin, floats_.pixels.begin() + end, to);
  else if (constant_)
    std::fill(to, to + (end - begin), value_);
  else
    toFloats(halves_.data() + begin, end - begin, std::ldexp(1.0f, -exponent_), to);
}

Image WindowImage::toImage() const {
  if (!packed()) return floats_;
  Image out;
  floats(out);
  return out;
}

Image& WindowImage::floats() {
  if (packed()) throw std::logic_error("WindowImage: packed, not in floats");
  return floats_;
}

const Image& WindowImage::floats() const {
  if (packed()) throw std::logic_error("WindowImage: packed, not in floats");
  return floats_;
}

}  // namespace dn::temporal
