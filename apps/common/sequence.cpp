#include "common/sequence.h"

#include <OpenImageIO/filesystem.h>
#include <fmt/format.h>

#include <algorithm>
#include <filesystem>
#include <set>

#include "common/cli.h"
#include "dn/io/buffer_io.h"

namespace fs = std::filesystem;
namespace Filesystem = OIIO::Filesystem;

namespace dn::cli {

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
    throw UsageError(path + ": not a frame pattern (use #, @ or %04d)");
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
    throw UsageError("--frames: '" + frames + "' is not a frame range such as 1-100 or 1-100x2");
  if (numbers.size() > kMaxFrames)
    throw UsageError(fmt::format("--frames: '{}' holds {} frames; at most {}", frames,
                                 numbers.size(), kMaxFrames));
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
    throw UsageError(pattern + ": cannot name frame " + std::to_string(frame));
  return names.front();
}

std::vector<std::pair<int, std::string>> sequenceFrames(const std::string& pattern,
                                                        const std::string& frames, bool skipMissing,
                                                        const std::string& tool) {
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
      throw IoError(
          fmt::format("{}: frames {} to {} are too far apart; give --frames", pattern, *lo, *hi));
    for (int f = *lo; f <= *hi; ++f) wanted.push_back(f);
  }
  std::vector<std::pair<int, std::string>> present;
  std::size_t missing = 0;
  for (int frame : std::set<int>(wanted.begin(), wanted.end())) {
    const std::string file = frameFile(pattern, frame);
    std::error_code ec;
    if (fs::is_regular_file(file, ec)) {
      present.emplace_back(frame, file);
    } else {
      fmt::print(stderr, "{}: {}: missing frame {}\n", tool, file, frame);
      ++missing;
    }
  }
  if (missing > 0 && !skipMissing)
    throw IoError(fmt::format("{}: {} missing frame(s); give --skip-missing to go on without them",
                              pattern, missing));
  if (present.empty()) throw IoError(pattern + ": no frames of the range exist");
  return present;
}

}  // namespace dn::cli
