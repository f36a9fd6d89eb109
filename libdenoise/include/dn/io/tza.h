// OIDN's TZA weight blobs: the format its trained networks are compiled into
// libOpenImageDenoise_core. A blob is the magic bytes D7 41, a major and minor
// version (2, 0), the uint64 offset of a tensor table; the table is a uint32
// count, then per tensor a uint16 name length and name, a uint8 rank, that many
// uint32 dims, a layout string of rank characters ("oihw", "x"), a data type
// ('h' half, 'f' float) and the uint64 offset of its data from the blob's start.
// Everything is little-endian. Plain C++: no LibTorch.
#pragma once

#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

namespace dn::tza {

// Every failure to parse: one line naming the source and what is wrong.
class TzaError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct Tensor {
  std::string name;           // e.g. "enc_conv0.weight"
  std::vector<int64_t> dims;  // e.g. {32, 9, 3, 3}
  std::string layout;         // "oihw" or "x"
  std::vector<float> values;  // converted to float, in the layout's order

  int64_t elementCount() const;
};

struct Blob {
  uint64_t offset = 0;  // where the blob starts in the file it came from
  uint64_t size = 0;    // bytes from the start to the end of its last table entry or data
  std::vector<Tensor> tensors;

  const Tensor* find(const std::string& name) const;  // nullptr if absent
  int64_t parameterCount() const;
};

// Parses the blob that starts at `offset` of `bytes`; `source` names the file
// in errors. Throws TzaError on a wrong magic or version, a table or tensor
// beyond the end, an unknown layout or data type, or dims that do not match
// the layout.
Blob parse(const std::string& bytes, uint64_t offset, const std::string& source);

// Every blob in `bytes` (a shared library, say): each occurrence of the magic
// and version that parses as a whole, in file order.
std::vector<Blob> scan(const std::string& bytes, const std::string& source);

// IEEE 754 half to float (subnormals, infinities and NaN included).
float halfToFloat(uint16_t half);

}  // namespace dn::tza
