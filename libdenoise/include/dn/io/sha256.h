// SHA-256 (FIPS 180-4) of bytes or of a file, as lowercase hex: provenance of
// imported weights and of the model behind an output.
#pragma once

#include <string>

namespace dn {

std::string sha256Hex(const std::string& bytes);
// Throws std::runtime_error naming the file when it cannot be read.
std::string sha256OfFile(const std::string& path);

}  // namespace dn
