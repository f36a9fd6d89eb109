// Writes TZA weight blobs (dn/io/tza.h) for tests: the format built by hand,
// byte by byte, independently of the reader.
#pragma once

#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

namespace dn::test {

struct TzaTensorSpec {
  std::string name;
  std::vector<uint32_t> dims;
  std::string layout;
  std::vector<uint16_t> halves;  // data as half bits
};

template <typename T>
void appendLittleEndian(std::string& out, T value) {
  char bytes[sizeof(T)];
  std::memcpy(bytes, &value, sizeof(T));  // the test machines are little-endian
  out.append(bytes, sizeof(T));
}

// Header, then every tensor's data, then the table.
inline std::string makeTzaBlob(const std::vector<TzaTensorSpec>& tensors) {
  std::string blob = "\xD7\x41\x02\x00";
  appendLittleEndian<uint64_t>(blob, 0);  // table offset, patched below
  std::vector<uint64_t> offsets;
  for (const auto& t : tensors) {
    while (blob.size() % 64) blob.push_back('\0');  // OIDN aligns tensor data
    offsets.push_back(blob.size());
    for (uint16_t h : t.halves) appendLittleEndian(blob, h);
  }
  const uint64_t table = blob.size();
  std::memcpy(&blob[4], &table, 8);
  appendLittleEndian<uint32_t>(blob, uint32_t(tensors.size()));
  for (size_t i = 0; i < tensors.size(); ++i) {
    const auto& t = tensors[i];
    appendLittleEndian<uint16_t>(blob, uint16_t(t.name.size()));
    blob += t.name;
    appendLittleEndian<uint8_t>(blob, uint8_t(t.dims.size()));
    for (uint32_t d : t.dims) appendLittleEndian(blob, d);
    blob += t.layout;
    blob += 'h';
    appendLittleEndian<uint64_t>(blob, offsets[i]);
  }
  return blob;
}

}  // namespace dn::test
