#include "dn/io/npy.h"

#include <unistd.h>

#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iterator>
#include <limits>

#include "dn/io/output_files.h"

namespace dn::npy {

namespace {

constexpr char kMagic[] = "\x93NUMPY";
constexpr std::size_t kMagicLength = 6;
constexpr std::size_t kAlignment = 64;         // numpy's ARRAY_ALIGN
constexpr std::size_t kGrowthAxisDigits = 21;  // numpy's GROWTH_AXIS_MAX_DIGITS
static_assert(sizeof(float) == 4, "float32 is assumed");

[[noreturn]] void fail(const std::string& path, const std::string& what) {
  throw NpyError(path + ": " + what);
}

std::size_t itemSize(DType dtype) { return dtype == DType::Float16 ? 2 : 4; }

// The header's Python dict literal, e.g.
//   {'descr': '<f4', 'fortran_order': False, 'shape': (256, 256, 3), }
// parsed strictly: exactly these three keys, nothing else.
class HeaderParser {
 public:
  HeaderParser(const std::string& text, const std::string& path) : s_(text), path_(path) {}

  void parse(std::string& descr, bool& fortranOrder, std::vector<int64_t>& shape) {
    bool seenDescr = false, seenOrder = false, seenShape = false;
    expect('{');
    while (!peek('}')) {
      const std::string key = quoted();
      expect(':');
      if (key == "descr" && !seenDescr) {
        descr = quoted();
        seenDescr = true;
      } else if (key == "fortran_order" && !seenOrder) {
        fortranOrder = boolean();
        seenOrder = true;
      } else if (key == "shape" && !seenShape) {
        shape = tuple();
        seenShape = true;
      } else {
        bad("unexpected or repeated key '" + key + "'");
      }
      if (!peek('}')) expect(',');
    }
    expect('}');
    skipSpace();
    if (pos_ != s_.size()) bad("text after the dict");
    if (!seenDescr || !seenOrder || !seenShape)
      bad("it lacks one of 'descr', 'fortran_order', 'shape'");
  }

 private:
  [[noreturn]] void bad(const std::string& what) { fail(path_, "malformed .npy header: " + what); }
  void skipSpace() {
    while (pos_ < s_.size() && std::isspace(static_cast<unsigned char>(s_[pos_]))) ++pos_;
  }
  bool peek(char c) {
    skipSpace();
    return pos_ < s_.size() && s_[pos_] == c;
  }
  void expect(char c) {
    if (!peek(c)) bad(std::string("expected '") + c + "'");
    ++pos_;
  }
  std::string quoted() {
    skipSpace();
    if (pos_ >= s_.size() || (s_[pos_] != '\'' && s_[pos_] != '"')) bad("expected a quoted string");
    const char quote = s_[pos_++];
    const std::size_t end = s_.find(quote, pos_);
    if (end == std::string::npos) bad("unterminated string");
    std::string out = s_.substr(pos_, end - pos_);
    pos_ = end + 1;
    return out;
  }
  bool boolean() {
    skipSpace();
    for (const char* word : {"True", "False"}) {
      if (s_.compare(pos_, std::strlen(word), word) == 0) {
        pos_ += std::strlen(word);
        return word[0] == 'T';
      }
    }
    bad("'fortran_order' is neither True nor False");
  }
  std::vector<int64_t> tuple() {
    std::vector<int64_t> out;
    expect('(');
    while (!peek(')')) {
      skipSpace();
      const std::size_t start = pos_;
      while (pos_ < s_.size() && std::isdigit(static_cast<unsigned char>(s_[pos_]))) ++pos_;
      if (pos_ == start || pos_ - start > 18) bad("a shape entry is not a non-negative integer");
      out.push_back(std::stoll(s_.substr(start, pos_ - start)));
      if (!peek(')')) expect(',');
    }
    expect(')');
    return out;
  }

  const std::string& s_;
  const std::string& path_;
  std::size_t pos_ = 0;
};

DType dtypeOf(const std::string& descr, const std::string& path) {
  if (descr == "<f4") return DType::Float32;
  if (descr == "<f2") return DType::Float16;
  if (descr == ">f4" || descr == ">f2")
    fail(path, "big-endian data ('" + descr + "'); save it as little-endian, e.g. a.astype('<" +
                   descr.substr(1) + "')");
  fail(path,
       "dtype '" + descr + "' is not supported: float32 or float16, little-endian ('<f4', '<f2')");
}

uint32_t littleEndian(const unsigned char* bytes, std::size_t count) {
  uint32_t value = 0;
  for (std::size_t i = 0; i < count; ++i) value |= uint32_t(bytes[i]) << (8 * i);
  return value;
}

std::string headerText(DType dtype, const std::vector<int64_t>& shape) {
  std::string dims;
  for (int64_t d : shape) dims += std::to_string(d) + ", ";
  if (shape.size() > 1)
    dims.resize(dims.size() - 2);  // (2, 3); a 1-d shape keeps (5,)
  else if (shape.size() == 1)
    dims.pop_back();
  std::string header = std::string("{'descr': '") + (dtype == DType::Float16 ? "<f2" : "<f4") +
                       "', 'fortran_order': False, 'shape': (" + dims + "), }";
  // numpy leaves room to grow the first axis in place.
  if (!shape.empty()) header.append(kGrowthAxisDigits - std::to_string(shape[0]).size(), ' ');
  const std::size_t used = kMagicLength + 2 + 2 + header.size() + 1;
  header.append((kAlignment - used % kAlignment) % kAlignment, ' ');
  return header + '\n';
}

}  // namespace

float halfToFloat(uint16_t half) {
  const uint32_t sign = uint32_t(half & 0x8000) << 16;
  const uint32_t exponent = (half >> 10) & 0x1f;
  const uint32_t mantissa = half & 0x3ff;
  if (exponent == 0) {  // zero or subnormal: mantissa * 2^-24
    const float magnitude = std::ldexp(float(mantissa), -24);
    return sign ? -magnitude : magnitude;
  }
  const uint32_t bits = exponent == 31 ? sign | 0x7f800000u | (mantissa << 13)
                                       : sign | ((exponent + 112) << 23) | (mantissa << 13);
  float out;
  std::memcpy(&out, &bits, sizeof out);
  return out;
}

uint16_t floatToHalf(float value) {
  uint32_t bits;
  std::memcpy(&bits, &value, sizeof bits);
  const uint16_t sign = uint16_t((bits >> 16) & 0x8000);
  const uint32_t magnitude = bits & 0x7fffffffu;
  if (magnitude > 0x7f800000u) return sign | 0x7e00 | uint16_t((magnitude >> 13) & 0x3ff);  // NaN
  if (magnitude >= 0x477ff000u) return sign | 0x7c00;  // >= 65520 rounds to infinity
  if (magnitude < 0x38800000u) {                       // below 2^-14: subnormal or zero
    // Exact scaling by 2^24, then round to nearest even (1024 is the smallest normal).
    return sign | uint16_t(std::nearbyint(std::fabs(value) * 16777216.0f));
  }
  uint32_t half = ((magnitude >> 23) - 112) << 10 | ((magnitude >> 13) & 0x3ff);
  const uint32_t rest = magnitude & 0x1fff;
  if (rest > 0x1000 || (rest == 0x1000 && (half & 1))) ++half;  // a carry moves into the exponent
  return sign | uint16_t(half);
}

Array read(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) fail(path, "cannot open (" + std::string(std::strerror(errno)) + ")");
  const std::string bytes{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
  if (in.bad()) fail(path, "read error");
  if (bytes.size() < kMagicLength + 4 || bytes.compare(0, kMagicLength, kMagic) != 0)
    fail(path, "not a .npy file (no \\x93NUMPY magic)");
  const auto* raw = reinterpret_cast<const unsigned char*>(bytes.data());
  const int major = raw[6];
  if (major < 1 || major > 3)
    fail(path, ".npy format version " + std::to_string(major) + "." + std::to_string(raw[7]) +
                   " is not supported (1.0 to 3.0)");
  const std::size_t lengthBytes = major == 1 ? 2 : 4;
  const std::size_t start = kMagicLength + 2 + lengthBytes;
  if (bytes.size() < start) fail(path, "truncated header");
  const std::size_t headerLength = littleEndian(raw + kMagicLength + 2, lengthBytes);
  if (bytes.size() < start + headerLength) fail(path, "truncated header");

  std::string descr;
  bool fortranOrder = false;
  Array array;
  HeaderParser(bytes.substr(start, headerLength), path).parse(descr, fortranOrder, array.shape);
  array.stored = dtypeOf(descr, path);
  if (fortranOrder)
    fail(path, "Fortran-ordered data; save it in C order (numpy.ascontiguousarray)");

  std::size_t count = 1;
  for (int64_t d : array.shape) {
    if (d != 0 && count > std::numeric_limits<std::size_t>::max() / 8 / std::size_t(d))
      fail(path, "shape too large");
    count *= std::size_t(d);
  }
  const std::size_t dataBytes = bytes.size() - start - headerLength;
  const std::size_t expected = count * itemSize(array.stored);
  if (dataBytes != expected)
    fail(path, "holds " + std::to_string(dataBytes) + " data bytes, its shape needs " +
                   std::to_string(expected) + (dataBytes < expected ? " (truncated)" : ""));

  array.values.resize(count);
  const char* data = bytes.data() + start + headerLength;
  if (array.stored == DType::Float32) {
    std::memcpy(array.values.data(), data, expected);  // x86 and ARM are little-endian
  } else {
    for (std::size_t i = 0; i < count; ++i) {
      uint16_t half;
      std::memcpy(&half, data + 2 * i, 2);
      array.values[i] = halfToFloat(half);
    }
  }
  return array;
}

void write(const std::string& path, const std::vector<int64_t>& shape,
           const std::vector<float>& values, DType dtype) {
  std::size_t count = 1;
  for (int64_t d : shape) {
    if (d < 0) fail(path, "negative shape entry");
    count *= std::size_t(d);
  }
  if (count != values.size())
    fail(path, "shape holds " + std::to_string(count) + " values, given " +
                   std::to_string(values.size()));
  const std::string header = headerText(dtype, shape);
  std::string out = std::string(kMagic, kMagicLength) + '\x01' + '\x00';
  out += char(header.size() & 0xff);
  out += char(header.size() >> 8);
  out += header;
  const std::size_t dataStart = out.size();
  out.resize(dataStart + count * itemSize(dtype));
  if (dtype == DType::Float32) {
    std::memcpy(&out[dataStart], values.data(), count * 4);
  } else {
    for (std::size_t i = 0; i < count; ++i) {
      const uint16_t half = floatToHalf(values[i]);
      std::memcpy(&out[dataStart + 2 * i], &half, 2);
    }
  }

  const std::string temporary = path + ".tmp" + std::to_string(getpid());
  trackTemporaryFile(temporary);
  {
    std::ofstream file(temporary, std::ios::binary | std::ios::trunc);
    file.write(out.data(), std::streamsize(out.size()));
    file.close();
    if (!file) {
      std::remove(temporary.c_str());
      untrackTemporaryFile(temporary);
      fail(path, "cannot write (" + std::string(std::strerror(errno)) + ")");
    }
  }
  if (std::rename(temporary.c_str(), path.c_str()) != 0) {
    const std::string reason = std::strerror(errno);
    std::remove(temporary.c_str());
    untrackTemporaryFile(temporary);
    fail(path, "cannot write (" + reason + ")");
  }
  untrackTemporaryFile(temporary);
}

Image readImage(const std::string& path) {
  Array array = read(path);
  if (array.shape.size() != 2 && array.shape.size() != 3)
    fail(path, "an image is (height, width) or (height, width, channels); this array has " +
                   std::to_string(array.shape.size()) + " dimensions");
  const int64_t channels = array.shape.size() == 3 ? array.shape[2] : 1;
  const int64_t limit = std::numeric_limits<int>::max();
  if (array.shape[0] < 1 || array.shape[1] < 1 || channels < 1 || array.shape[0] > limit ||
      array.shape[1] > limit || channels > 64)
    fail(path, "image shape out of range");
  Image image;
  image.height = int(array.shape[0]);
  image.width = int(array.shape[1]);
  image.channels = int(channels);
  image.pixels = std::move(array.values);
  return image;
}

void writeImage(const std::string& path, const Image& image, DType dtype) {
  write(path, {image.height, image.width, image.channels}, image.pixels, dtype);
}

FrameBuffers readFrameFolder(const std::string& dir) {
  FrameBuffers frame;
  const std::string colorPath = dir + "/color.npy";
  if (!std::ifstream(colorPath)) throw NpyError(colorPath + ": missing (the colour is required)");
  for (const BufferSpec& spec : canonicalBuffers()) {
    const std::string path = dir + "/" + spec.name + ".npy";
    if (!std::ifstream(path)) continue;
    Image image = readImage(path);
    if (image.channels != spec.channels)
      throw NpyError(path + ": " + std::to_string(image.channels) + " channels, " + spec.name +
                     " has " + std::to_string(spec.channels));
    if (frame.buffers.empty()) {
      frame.width = image.width;
      frame.height = image.height;
    } else if (image.width != frame.width || image.height != frame.height) {
      throw NpyError(path + ": " + std::to_string(image.width) + "x" +
                     std::to_string(image.height) + ", the colour is " +
                     std::to_string(frame.width) + "x" + std::to_string(frame.height));
    }
    frame.buffers[spec.name] = std::move(image);
  }
  frame.dataWindow = frame.displayWindow = {0, 0, frame.width, frame.height};
  return frame;
}

}  // namespace dn::npy
