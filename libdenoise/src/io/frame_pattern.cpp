#include "dn/io/frame_pattern.h"

#include <OpenImageIO/filesystem.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <set>
#include <stdexcept>

#include "dn/io/buffer_io.h"

namespace fs = std::filesystem;
namespace Filesystem = OIIO::Filesystem;

namespace dn {

namespace {

// A range beyond this is a typo ("1-1000000"), not a shot.
constexpr std::size_t kMaxFrames = 100000;

struct Pattern {
  std::string printf;  // "shot.%04d.exr"
  std::string range;   // "1-100" from "shot.1-100#.exr", or ""
};

Pattern parse(const std::string& path) {
  Pattern p;
  if (!Filesystem::parse_pattern(path.c_str(), 0, p.printf, p.range))
    throw std::invalid_argument(path + ": not a frame pattern (use #, @ or %04d)");
  return p;
}

}  // namespace

std::vector<int> parseFrameRange(const std::string& frames) {
  // OIIO reads "1-10x0" as step 1 and runs to any length: check the shape first.
  const bool shaped = !frames.empty() &&
                      frames.find_first_not_of("0123456789-x,") == std::string::npos &&
                      frames.find("x0") == std::string::npos;
  std::vector<int> numbers;
  if (!shaped || !Filesystem::enumerate_sequence(frames, numbers) || numbers.empty())
    throw std::invalid_argument("--frames: '" + frames +
                                "' is not a frame range such as 1-100 or 1-100x2");
  if (numbers.size() > kMaxFrames)
    throw std::invalid_argument("--frames: '" + frames + "' holds " +
                                std::to_string(numbers.size()) + " frames; at most " +
                                std::to_string(kMaxFrames));
  return numbers;
}

bool isFramePattern(const std::string& path) {
  std::error_code ec;
  if (fs::exists(path, ec)) return false;
  std::string printf, range;
  return Filesystem::parse_pattern(path.c_str(), 0, printf, range);
}

std::string frameFile(const std::string& pattern, int frame) {
  std::vector<std::string> names;
  if (!Filesystem::enumerate_file_sequence(parse(pattern).printf, {frame}, names) || names.empty())
    throw std::invalid_argument(pattern + ": cannot name frame " + std::to_string(frame));
  return names.front();
}

std::optional<int> frameNumberOf(const std::string& pattern, const std::string& path) {
  std::string printf, range;
  if (!Filesystem::parse_pattern(pattern.c_str(), 0, printf, range)) return std::nullopt;
  const auto percent = printf.find('%');
  const auto d = printf.find('d', percent);
  if (percent == std::string::npos || d == std::string::npos) return std::nullopt;
  const std::string head = printf.substr(0, percent), tail = printf.substr(d + 1);
  if (path.size() <= head.size() + tail.size() || path.compare(0, head.size(), head) != 0 ||
      path.compare(path.size() - tail.size(), tail.size(), tail) != 0)
    return std::nullopt;
  const std::string digits = path.substr(head.size(), path.size() - head.size() - tail.size());
  char* end = nullptr;
  const long n = std::strtol(digits.c_str(), &end, 10);
  if (digits.empty() || *end != '\0') return std::nullopt;
  if (frameFile(pattern, static_cast<int>(n)) != path) return std::nullopt;
  return static_cast<int>(n);
}

PatternFrames patternFrames(const std::string& pattern, const std::string& frames) {
  const Pattern p = parse(pattern);
  std::vector<int> wanted;
  if (!frames.empty() || !p.range.empty()) {
    wanted = parseFrameRange(frames.empty() ? p.range : frames);
  } else {
    // No range: the files on disk, and every gap between the first and the last.
    std::vector<int> found;
    std::vector<std::string> files;
    Filesystem::scan_for_matching_filenames(p.printf, found, files);
    if (found.empty()) throw IoError(pattern + ": no frames match this pattern");
    const auto [lo, hi] = std::minmax_element(found.begin(), found.end());
    if (std::size_t(*hi - *lo) >= kMaxFrames)
      throw IoError(pattern + ": frames " + std::to_string(*lo) + " to " + std::to_string(*hi) +
                    " are too far apart; give --frames");
    for (int f = *lo; f <= *hi; ++f) wanted.push_back(f);
  }
  PatternFrames result;
  for (int frame : std::set<int>(wanted.begin(), wanted.end())) {
    std::string file = frameFile(pattern, frame);
    std::error_code ec;
    (fs::is_regular_file(file, ec) ? result.present : result.missing)
        .emplace_back(frame, std::move(file));
  }
  return result;
}

}  // namespace dn
