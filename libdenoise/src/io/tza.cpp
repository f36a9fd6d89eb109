#include "dn/io/tza.h"

#include <cmath>
#include <cstring>

namespace dn::tza {
namespace {

constexpr unsigned char kMagic0 = 0xD7, kMagic1 = 0x41;
constexpr int kMajorVersion = 2;

// Bounds-checked little-endian reads over one blob.
class Reader {
 public:
  Reader(const std::string& bytes, uint64_t pos, const std::string& source)
      : bytes_(bytes), pos_(pos), source_(source) {}

  template <typename T>
  T read(const char* what) {
    need(sizeof(T), what);
    T value;
    std::memcpy(&value, bytes_.data() + pos_, sizeof(T));
    pos_ += sizeof(T);
    return value;
  }
  std::string text(size_t length, const char* what) {
    need(length, what);
    std::string value = bytes_.substr(pos_, length);
    pos_ += length;
    return value;
  }
  void need(uint64_t length, const char* what) const {
    if (pos_ > bytes_.size() || bytes_.size() - pos_ < length)
      fail(std::string(what) + " is truncated");
  }
  [[noreturn]] void fail(const std::string& problem) const {
    throw TzaError(source_ + ": weight blob: " + problem);
  }
  uint64_t pos() const { return pos_; }
  void seek(uint64_t pos) { pos_ = pos; }

 private:
  const std::string& bytes_;
  uint64_t pos_;
  const std::string& source_;
};

void readValues(const std::string& bytes, uint64_t at, char type, Tensor& tensor) {
  const size_t count = static_cast<size_t>(tensor.elementCount());
  tensor.values.resize(count);
  const char* data = bytes.data() + at;
  for (size_t i = 0; i < count; ++i) {
    if (type == 'h') {
      uint16_t h;
      std::memcpy(&h, data + 2 * i, 2);
      tensor.values[i] = halfToFloat(h);
    } else {
      std::memcpy(&tensor.values[i], data + 4 * i, 4);
    }
  }
}

}  // namespace

int64_t Tensor::elementCount() const {
  int64_t count = 1;
  for (int64_t d : dims) count *= d;
  return count;
}

const Tensor* Blob::find(const std::string& name) const {
  for (const auto& tensor : tensors)
    if (tensor.name == name) return &tensor;
  return nullptr;
}

int64_t Blob::parameterCount() const {
  int64_t count = 0;
  for (const auto& tensor : tensors) count += tensor.elementCount();
  return count;
}

float halfToFloat(uint16_t half) {
  const int sign = (half >> 15) ? -1 : 1;
  const int exponent = (half >> 10) & 0x1F;
  const int mantissa = half & 0x3FF;
  if (exponent == 0) return sign * std::ldexp(float(mantissa), -24);
  if (exponent == 31) return mantissa ? NAN : sign * INFINITY;
  return sign * std::ldexp(float(mantissa | 0x400), exponent - 25);
}

Blob parse(const std::string& bytes, uint64_t offset, const std::string& source) {
  Reader in(bytes, offset, source);
  if (in.read<uint8_t>("magic") != kMagic0 || in.read<uint8_t>("magic") != kMagic1)
    in.fail("wrong magic bytes (not a TZA blob)");
  const int major = in.read<uint8_t>("version");
  in.read<uint8_t>("version");
  if (major != kMajorVersion)
    in.fail("version " + std::to_string(major) + " is not supported (expected 2)");
  const uint64_t tableOffset = in.read<uint64_t>("table offset");
  if (tableOffset > bytes.size() - offset) in.fail("tensor table lies beyond the end of the file");
  in.seek(offset + tableOffset);
  const uint32_t count = in.read<uint32_t>("tensor count");
  if (count == 0 || count > 4096) in.fail("implausible tensor count " + std::to_string(count));

  Blob blob;
  blob.offset = offset;
  uint64_t end = 0;
  for (uint32_t i = 0; i < count; ++i) {
    Tensor tensor;
    tensor.name = in.text(in.read<uint16_t>("tensor name length"), "tensor name");
    const int rank = in.read<uint8_t>("tensor rank");
    for (int d = 0; d < rank; ++d) tensor.dims.push_back(in.read<uint32_t>("tensor dims"));
    tensor.layout = in.text(rank, "tensor layout");
    if (tensor.layout != "oihw" && tensor.layout != "x")
      in.fail("tensor '" + tensor.name + "' has unknown layout '" + tensor.layout + "'");
    const char type = in.read<char>("tensor data type");
    if (type != 'h' && type != 'f')
      in.fail("tensor '" + tensor.name + "' has unknown data type '" + std::string(1, type) + "'");
    const uint64_t dataOffset = in.read<uint64_t>("tensor data offset");
    const uint64_t dataBytes = uint64_t(tensor.elementCount()) * (type == 'h' ? 2 : 4);
    if (dataOffset > bytes.size() - offset || bytes.size() - offset - dataOffset < dataBytes)
      in.fail("data of tensor '" + tensor.name + "' lies beyond the end of the file");
    readValues(bytes, offset + dataOffset, type, tensor);
    end = std::max(end, dataOffset + dataBytes);
    blob.tensors.push_back(std::move(tensor));
  }
  blob.size = std::max(end, in.pos() - offset);
  return blob;
}

std::vector<Blob> scan(const std::string& bytes, const std::string& source) {
  const std::string signature = {char(kMagic0), char(kMagic1), char(kMajorVersion), 0};
  std::vector<Blob> blobs;
  for (size_t pos = bytes.find(signature); pos != std::string::npos;
       pos = bytes.find(signature, pos + 1)) {
    try {
      blobs.push_back(parse(bytes, pos, source));
      pos += blobs.back().size - 1;
    } catch (const TzaError&) {
      // The signature's four bytes also occur by chance in code and data.
    }
  }
  return blobs;
}

}  // namespace dn::tza
