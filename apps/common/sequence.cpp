#include "common/sequence.h"

#include <fmt/format.h>

#include "dn/io/buffer_io.h"

namespace dn::cli {

std::vector<std::pair<int, std::string>> sequenceFrames(const std::string& pattern,
                                                        const std::string& frames, bool skipMissing,
                                                        const std::string& tool) {
  PatternFrames found = patternFrames(pattern, frames);
  for (const auto& [frame, file] : found.missing)
    fmt::print(stderr, "{}: {}: missing frame {}\n", tool, file, frame);
  if (!found.missing.empty() && !skipMissing)
    throw IoError(fmt::format("{}: {} missing frame(s); give --skip-missing to go on without them",
                              pattern, found.missing.size()));
  if (found.present.empty()) throw IoError(pattern + ": no frames of the range exist");
  return std::move(found.present);
}

}  // namespace dn::cli
