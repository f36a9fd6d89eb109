// The frames of a tool's input pattern (dn/io/frame_pattern.h), with one line
// on stderr for each frame of the range that is missing.
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "dn/io/frame_pattern.h"

namespace dn::cli {

// The frames of an input pattern as (frame number, file): the range given by
// `frames` (--frames), else the pattern's own range, else every matching file
// on disk. Each frame of the range that is missing gets one line on stderr
// ("<tool>: <file>: missing frame N"); then the run stops unless skipMissing.
std::vector<std::pair<int, std::string>> sequenceFrames(const std::string& pattern,
                                                        const std::string& frames, bool skipMissing,
                                                        const std::string& tool);

}  // namespace dn::cli
