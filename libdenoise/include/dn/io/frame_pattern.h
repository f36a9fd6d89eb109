// Frame sequences as oiiotool spells them, through OpenImageIO's own parser:
// "#" is four digits, "@" one ("shot.#.exr" = shot.0001.exr, "shot.@@@.exr" =
// shot.001.exr), "%04d" as in printf, and ranges such as "shot.1-100#.exr" or
// a frame range "1-100x2".
#pragma once

#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace dn {

// True when `path` is a frame pattern rather than a file name (a file that
// exists under that exact name is a file, even if it holds '#' or '@').
bool isFramePattern(const std::string& path);

// The file of frame `frame` of a pattern; throws std::invalid_argument when
// `pattern` is not one.
std::string frameFile(const std::string& pattern, int frame);

// The frame number of `path` in `pattern` ("shot.#.exr"), or nullopt.
std::optional<int> frameNumberOf(const std::string& pattern, const std::string& path);

// Checks a frame range ("1-100x2", "1,5,9") and returns its frame numbers;
// throws std::invalid_argument naming it (as --frames) when it is not one.
std::vector<int> parseFrameRange(const std::string& frames);

// The frames of a pattern as (frame number, file), in frame order: the range
// `frames`, else the pattern's own range, else every frame from the first to
// the last file on disk. Throws IoError when no file matches a pattern without
// a range, or the files found lie too far apart.
struct PatternFrames {
  std::vector<std::pair<int, std::string>> present;
  std::vector<std::pair<int, std::string>> missing;  // in the range, not on disk
};
PatternFrames patternFrames(const std::string& pattern, const std::string& frames = "");

}  // namespace dn
