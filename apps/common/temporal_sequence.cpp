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

// A frame as read: its guides and motion, its noisy colour and, once denoised
// alone, its result. The buffers the model reads are dropped once denoised, so
// a window of 1080p frames holds about 0.13 GB a frame, not the whole file.
struct TemporalSequence::Input {
  FrameBuffers buffers;         // what the model reads, until denoised
  temporal::WindowFrame frame;  // noisy, guides, motion; denoised
};

namespace {

// The albedo, normal and depth of a frame file: the guides of reprojection.
// Taken from the buffers already read where the model reads them (one
// decoding of the file less), else read.
motion::Guides guidesOf(const FrameBuffers& frame, const std::string& path,
                        const ReadOptions& base) {
  ReadOptions read = base;
  read.only = {"color"};
  for (const auto& b : availableBuffers(path, base))
    if ((b == "albedo" || b == "normal" || b == "depth") && !frame.has(b)) read.only.push_back(b);
  const FrameBuffers extra = read.only.size() > 1 ? readFrame(path, read) : FrameBuffers();
  auto guide = [&](const std::string& name) {
    return frame.has(name) ? frame.get(name) : extra.has(name) ? extra.get(name) : Image();
  };
  motion::Guides g;
  g.albedo = guide("albedo");
  g.normal = guide("normal");
  g.depth = guide("depth");
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

std::shared_ptr<TemporalSequence::Input> TemporalSequence::input(int number,
                                                                 const FrameBuffers* given,
                                                                 const Read& read) {
  if (auto it = inputs_.find(number); it != inputs_.end()) return it->second;
  const std::string path = fileOf(number);
  if (path.empty()) return nullptr;
  auto entry = std::make_shared<Input>();
  // A given frame is denoised straight from the caller's buffers.
  if (!given) entry->buffers = read(path);
  const FrameBuffers& frame = given ? *given : entry->buffers;
  entry->frame.noisy = frame.get("color");
  entry->frame.guides = guidesOf(frame, path, settings_.read);
  std::optional<motion::MotionField> field =
      settings_.motion.empty()
          ? motion::readMotion(path, frame.width, frame.height, settings_.read.viewLayer)
          : motion::readMotion(frameFile(settings_.motion, number), frame.width, frame.height, "",
                               true);
  if (field) entry->frame.motion = std::move(*field);
  inputs_[number] = entry;
  return entry;
}

std::shared_ptr<const DenoiseResult> TemporalSequence::estimate(int number,
                                                                const FrameBuffers* given,
                                                                const Read& read,
                                                                const Denoise& denoise) {
  if (auto it = estimates_.find(number); it != estimates_.end()) return it->second;
  auto self = input(number, given, read);
  if (!self) return nullptr;
  auto result =
      std::make_shared<DenoiseResult>(denoise(fileOf(number), given ? *given : self->buffers));
  self->buffers = FrameBuffers();
  self->frame.denoised = std::move(result->color);  // the filter's input, held once
  return estimates_[number] = result;
}

void TemporalSequence::forget(int number) {
  // Memory stays bounded by the window: what lies behind it is dropped.
  const int reach = settings_.radius;
  for (auto it = inputs_.begin(); it != inputs_.end();)
    it = (it->first < number - reach || it->first > number + reach) ? inputs_.erase(it)
                                                                    : std::next(it);
  for (auto it = estimates_.begin(); it != estimates_.end();)
    it = (it->first < number - settings_.radius || it->first > number + settings_.radius)
             ? estimates_.erase(it)
             : std::next(it);
}

DenoiseResult TemporalSequence::denoise(const std::string& input, const FrameBuffers& frame,
                                        const Read& read, const Denoise& denoise) {
  const int n = numbers_.at(input);
  const int radius = settings_.radius;
  forget(n);
  lastNumber_ = n;
  // The window's frames stay held by inputs_ until the next call's forget().
  std::shared_ptr<const DenoiseResult> centre;
  std::vector<const temporal::WindowFrame*> window;
  for (int m = n - radius; m <= n + radius; ++m) {
    auto result = estimate(m, m == n ? &frame : nullptr, read, denoise);
    if (m == n) centre = result;
    auto source = result ? this->input(m, nullptr, read) : nullptr;
    const bool usable = source && source->frame.denoised.sameShape(frame.get("color"));
    window.push_back(usable ? &source->frame : nullptr);
  }
  temporal::TemporalOptions options = settings_.filter;
  options.radius = radius;
  temporal::TemporalResult filtered = temporal::filterFrame(window, radius, options);
  lastStats_ = filtered.stats;
  DenoiseResult result = *centre;
  result.color = std::move(filtered.color);
  return result;
}

std::string TemporalSequence::report() const {
  std::string line = fmt::format("frame {}: {:.0f}% from history ({} neighbour{}", lastNumber_,
                                 100 * lastStats_.historyShare, lastStats_.neighbours,
                                 lastStats_.neighbours == 1 ? "" : "s");
  if (lastStats_.repeatedNoise > 0)
    line += fmt::format(", {} repeating its noise and left out", lastStats_.repeatedNoise);
  if (lastStats_.relit > 0)
    line += fmt::format(", {} brought to its light first", lastStats_.relit);
  if (lastStats_.changedLight > 0)
    line += fmt::format(", {} with the light changed over the frame and left out",
                        lastStats_.changedLight);
  return line + ")";
}

}  // namespace dn::cli
