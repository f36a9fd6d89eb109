#include "common/temporal_sequence.h"

#include <OpenImageIO/filesystem.h>
#include <fmt/format.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>

#include "common/cli.h"
#include "common/sequence.h"
#include "dn/motion/motion.h"

namespace fs = std::filesystem;

namespace dn::cli {

struct TemporalSequence::Entry {
  DenoiseResult result;  // the frame denoised alone
  temporal::WindowFrame frame;
};

namespace {

// The frame number of `path` in `pattern` ("shot.#.exr", "shot.%04d.exr"), or
// nullopt when it is not one of its frames.
std::optional<int> frameNumberOf(const std::string& pattern, const std::string& path) {
  std::string printf, range;
  if (!OIIO::Filesystem::parse_pattern(pattern.c_str(), 0, printf, range)) return std::nullopt;
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

// The albedo, normal and depth of a frame file: the guides of reprojection.
motion::Guides readGuides(const std::string& path, const ReadOptions& base) {
  ReadOptions read = base;
  read.only = {"color"};
  for (const auto& b : availableBuffers(path, base))
    if (b == "albedo" || b == "normal" || b == "depth") read.only.push_back(b);
  FrameBuffers frame = readFrame(path, read);
  motion::Guides g;
  if (frame.has("albedo")) g.albedo = frame.get("albedo");
  if (frame.has("normal")) g.normal = frame.get("normal");
  if (frame.has("depth")) g.depth = frame.get("depth");
  return g;
}

}  // namespace

TemporalSequence::TemporalSequence(std::string pattern, std::map<std::string, int> numbers,
                                   TemporalSettings settings)
    : pattern_(std::move(pattern)), numbers_(std::move(numbers)), settings_(std::move(settings)) {}

std::unique_ptr<TemporalSequence> TemporalSequence::plan(const std::vector<std::string>& inputs,
                                                         const std::vector<std::string>& jobInputs,
                                                         const TemporalSettings& settings,
                                                         std::string& why) {
  why.clear();
  if (!settings.enabled || inputs.size() != 1 || !isFramePattern(inputs.front()) ||
      jobInputs.empty())
    return nullptr;
  std::map<std::string, int> numbers;
  for (const auto& input : jobInputs)
    if (auto n = frameNumberOf(inputs.front(), input)) numbers[input] = *n;
  if (numbers.size() != jobInputs.size()) return nullptr;
  const std::string& first = jobInputs.front();
  if (!settings.motion.empty()) {
    if (!isFramePattern(settings.motion))
      throw UsageError("--motion " + settings.motion + ": a sequence needs a motion pattern");
  } else if (!motion::findMotionChannels(channelNames(first), settings.read.viewLayer)) {
    why = first +
          ": no motion vectors (Blender: the Vector pass, motion blur off; or --motion FILES); "
          "denoising frame by frame";
    return nullptr;
  }
  return std::unique_ptr<TemporalSequence>(
      new TemporalSequence(inputs.front(), std::move(numbers), settings));
}

std::string TemporalSequence::fileOf(int number) const {
  const std::string path = frameFile(pattern_, number);
  std::error_code ec;
  return fs::exists(path, ec) ? path : std::string();
}

std::shared_ptr<const TemporalSequence::Entry> TemporalSequence::load(int number,
                                                                      const FrameBuffers* given,
                                                                      const Read& read,
                                                                      const Denoise& denoise) {
  if (auto it = window_.find(number); it != window_.end()) return it->second;
  const std::string path = fileOf(number);
  if (path.empty()) return nullptr;
  const FrameBuffers frame = given ? *given : read(path);
  auto entry = std::make_shared<Entry>();
  entry->result = denoise(frame);
  entry->frame.denoised = entry->result.color;
  entry->frame.noisy = frame.get("color");
  entry->frame.guides = readGuides(path, settings_.read);
  std::optional<motion::MotionField> field =
      settings_.motion.empty()
          ? motion::readMotion(path, frame.width, frame.height, settings_.read.viewLayer)
          : motion::readMotion(frameFile(settings_.motion, number), frame.width, frame.height, "",
                               true);
  if (field) entry->frame.motion = std::move(*field);
  window_[number] = entry;
  return entry;
}

DenoiseResult TemporalSequence::denoise(const std::string& input, const FrameBuffers& frame,
                                        const Read& read, const Denoise& denoise) {
  const int n = numbers_.at(input);
  const int radius = settings_.radius;
  // Memory stays bounded by the window: frames behind it are dropped.
  for (auto it = window_.begin(); it != window_.end();)
    it = (it->first < n - radius || it->first > n + radius) ? window_.erase(it) : std::next(it);
  std::vector<std::shared_ptr<const Entry>> held;
  std::vector<const temporal::WindowFrame*> window;
  for (int m = n - radius; m <= n + radius; ++m) {
    auto entry = load(m, m == n ? &frame : nullptr, read, denoise);
    const bool usable = entry && entry->frame.denoised.sameShape(frame.get("color"));
    held.push_back(entry);
    window.push_back(usable ? &entry->frame : nullptr);
  }
  temporal::TemporalOptions options;
  options.radius = radius;
  temporal::TemporalResult filtered = temporal::filterFrame(window, radius, options);
  lastStats_ = filtered.stats;
  lastNumber_ = n;
  DenoiseResult result = held[radius]->result;
  result.color = std::move(filtered.color);
  return result;
}

std::string TemporalSequence::report() const {
  std::string line = fmt::format("frame {}: {:.0f}% from history ({} neighbour{}", lastNumber_,
                                 100 * lastStats_.historyShare, lastStats_.neighbours,
                                 lastStats_.neighbours == 1 ? "" : "s");
  if (lastStats_.repeatedNoise > 0)
    line += fmt::format(", {} repeating its noise and left out", lastStats_.repeatedNoise);
  return line + ")";
}

}  // namespace dn::cli
