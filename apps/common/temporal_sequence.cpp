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

// A frame as read: the buffers the model reads, and its guides and motion.
struct TemporalSequence::Input {
  FrameBuffers buffers;
  temporal::WindowFrame frame;  // noisy, guides, motion (denoised filled per use)
};

namespace {

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

std::shared_ptr<const TemporalSequence::Input> TemporalSequence::input(int number,
                                                                       const FrameBuffers* given,
                                                                       const Read& read) {
  if (auto it = inputs_.find(number); it != inputs_.end()) return it->second;
  const std::string path = fileOf(number);
  if (path.empty()) return nullptr;
  auto entry = std::make_shared<Input>();
  entry->buffers = given ? *given : read(path);
  const FrameBuffers& frame = entry->buffers;
  entry->frame.noisy = frame.get("color");
  entry->frame.guides = readGuides(path, settings_.read);
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
  if (settings_.mode == TemporalMode::Filter)
    return estimates_[number] =
               std::make_shared<DenoiseResult>(denoise(fileOf(number), self->buffers));
  const int radius = settings_.radius;
  std::vector<std::shared_ptr<const Input>> held;
  std::vector<const FrameBuffers*> buffers;
  std::vector<const temporal::WindowFrame*> window;
  for (int m = number - radius; m <= number + radius; ++m) {
    auto entry = m == number ? self : input(m, nullptr, read);
    const bool usable = entry && entry->buffers.width == self->buffers.width &&
                        entry->buffers.height == self->buffers.height;
    held.push_back(entry);
    buffers.push_back(usable ? &entry->buffers : nullptr);
    window.push_back(usable ? &entry->frame : nullptr);
  }
  temporal::TemporalOptions options = settings_.filter;
  options.radius = radius;
  temporal::TemporalStats stats;
  const FrameBuffers accumulated =
      temporal::accumulateInputs(buffers, window, radius, options, stats);
  lastStats_ = stats;
  return estimates_[number] = std::make_shared<DenoiseResult>(denoise(fileOf(number), accumulated));
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
  if (settings_.mode == TemporalMode::Accumulate) return *estimate(n, &frame, read, denoise);
  std::vector<std::shared_ptr<const DenoiseResult>> held;
  std::vector<temporal::WindowFrame> frames(2 * radius + 1);
  std::vector<const temporal::WindowFrame*> window;
  for (int m = n - radius; m <= n + radius; ++m) {
    auto result = estimate(m, m == n ? &frame : nullptr, read, denoise);
    auto source = result ? this->input(m, nullptr, read) : nullptr;
    const bool usable = result && result->color.sameShape(frame.get("color"));
    held.push_back(result);
    if (usable) {
      temporal::WindowFrame& f = frames[m - (n - radius)];
      f = source->frame;
      f.denoised = result->color;
    }
    window.push_back(usable ? &frames[m - (n - radius)] : nullptr);
  }
  temporal::TemporalOptions options = settings_.filter;
  options.radius = radius;
  temporal::TemporalResult filtered = temporal::filterFrame(window, radius, options);
  lastStats_ = filtered.stats;
  DenoiseResult result = *held[radius];
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
