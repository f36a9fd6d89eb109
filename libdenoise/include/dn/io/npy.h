// NumPy's .npy format, strictly: float32 or float16, little-endian, C order,
// format versions 1.0 to 3.0. Raw render buffers in and out where OpenImageIO is
// not at hand (the inference core alone, bench/denoise_npy_bench, the GPU check).
// Anything else is refused with one line naming the file and what is wrong.
#pragma once

#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include "dn/image.h"
#include "dn/io/buffers.h"

namespace dn::npy {

enum class DType { Float16, Float32 };

struct NpyError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

struct Array {
  std::vector<int64_t> shape;  // as numpy gives it; () is one value
  std::vector<float> values;   // C order, converted to float32
  DType stored = DType::Float32;
};

// Throws NpyError: "<path>: <what is wrong>".
Array read(const std::string& path);
// Written as numpy.save writes it (format 1.0, header padded to 64 bytes), to a
// temporary file renamed into place: no partial output. Throws NpyError.
void write(const std::string& path, const std::vector<int64_t>& shape,
           const std::vector<float>& values, DType dtype = DType::Float32);

// An image as a (height, width, channels) array; (height, width) reads as one channel.
Image readImage(const std::string& path);
void writeImage(const std::string& path, const Image& image, DType dtype = DType::Float32);

// A frame as a folder of <canonical buffer name>.npy files (color.npy,
// albedo.npy, ...; other files are ignored), each (height, width, channels)
// of the buffer's channel count and all of the colour's size. Throws NpyError
// naming the file that is missing, malformed or of another shape.
FrameBuffers readFrameFolder(const std::string& dir);

// IEEE 754 binary16 conversions (round to nearest even), as numpy's float16.
float halfToFloat(uint16_t half);
uint16_t floatToHalf(float value);

}  // namespace dn::npy
