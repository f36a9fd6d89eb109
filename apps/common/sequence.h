// Frame sequences as oiiotool spells them, through OpenImageIO's own parser:
// "#" is four digits, "@" one ("shot.#.exr" = shot.0001.exr, "shot.@@@.exr" =
// shot.001.exr), "%04d" as in printf, and ranges such as "shot.1-100#.exr" or
// --frames 1-100x2.
#pragma once

#include <string>
#include <utility>
#include <vector>

namespace dn::cli {

// True when `path` is a frame pattern rather than a file name (a file that
// exists under that exact name is a file, even if it holds '#' or '@').
bool isFramePattern(const std::string& path);

// The frames of an input pattern as (frame number, file): the range given by
// `frames` (--frames), else the pattern's own range, else every matching file
// on disk. Each frame of the range that is missing gets one line on stderr
// ("<tool>: <file>: missing frame N"); then the run stops unless skipMissing.
std::vector<std::pair<int, std::string>> sequenceFrames(const std::string& pattern,
                                                        const std::string& frames, bool skipMissing,
                                                        const std::string& tool);

// The file of frame `frame` of an output pattern.
std::string frameFile(const std::string& pattern, int frame);

// Checks a --frames value ("1-100x2", "1,5,9") and returns its frame numbers.
std::vector<int> parseFrameRange(const std::string& frames);

}  // namespace dn::cli
