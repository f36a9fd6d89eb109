#include "dn/temporal/sequence.h"

#include <algorithm>
#include <array>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <future>
#include <optional>
#include <set>
#include <stdexcept>
#include <utility>

#include "dn/io/frame_pattern.h"
#include "dn/motion/motion.h"
#include "dn/temporal/parallel.h"

namespace fs = std::filesystem;

namespace dn::temporal {

// The model's buffers a window frame holds as its noisy render and guides.
const char* const kHeldInWindow[] = {"color", "albedo", "normal", "depth"};

// A frame as read: its guides and motion, its noisy colour and, once denoised
// alone, its result. The buffers the model reads are dropped once denoised,
// and the window holds its images in half floats (WindowFrame), so a window
// of 1080p frames holds about 0.11 GB a frame.
struct Sequence::Input {
  // What the model reads; once denoised, all but the colour, albedo, normal
  // and depth, which `frame` holds (Sequence::frame puts them back), and the alpha.
  FrameBuffers buffers;
  std::set<std::string> heldInWindow;  // those of kHeldInWindow `frame` holds as read
  // Until the frame is denoised, `buffers` holds those of heldInWindow for the
  // network, and `frame` takes them after (holdInWindow): not both at once.
  bool heldInBuffers = false;
  WindowFrame frame;  // noisy, guides, motion; denoised
  WindowImage alpha;  // the colour's, in half floats where the file has it so
  // The prefilter's, for denoising the frame's history (rounded to half floats).
  WindowImage cleanAlbedo, cleanNormal;
  std::optional<HeldCompanions> companions;  // once made
  bool companionHistories = false;           // their histories made (companionHistories)
  std::optional<DeviceFrame> onDevice;       // SequenceSettings::filterDevice: the frame there
  bool inPast = false;                       // enterPast() done

  // Once the frame is in the past its own denoisings are done (a frame denoised
  // again with -n keeps them), and only a frame's own view-dependent share is
  // used: about 30 MB less a 1080p frame.
  void dropOwnUse() {
    cleanAlbedo = cleanNormal = WindowImage();
    frame.viewDependent = WindowImage();
  }

  // Once the frame is before the one filtered, its companions kept as made
  // are read no more, and its copy on the device holds its history as the
  // window does, in half floats.
  void enterPast(const std::optional<torch::Device>& device) {
    if (std::exchange(inPast, true)) return;
    if (companions)
      for (auto& [name, companion] : *companions)
        if (!companion.overTime) companion.image = WindowImage();
    if (onDevice) onDevice->history = pixelsToDevice(frame.history.toImage(), *device);
  }

  // The window's copies of the buffers of kHeldInWindow, in its order.
  std::array<WindowImage*, std::size(kHeldInWindow)> windowCopies() {
    return {&frame.noisy, &frame.guides.albedo, &frame.guides.normal, &frame.guides.depth};
  }
  std::array<const WindowImage*, std::size(kHeldInWindow)> windowCopies() const {
    return {&frame.noisy, &frame.guides.albedo, &frame.guides.normal, &frame.guides.depth};
  }
  // The frame's buffers as read, put back together without decoding the file
  // again, but for those of kHeldInWindow in `replaced` (the caller's own).
  FrameBuffers readAgain(const std::set<std::string>& replaced = {}) const;
  // Drops the buffers the window frame holds too (only readAgain needs them).
  void dropHeld() {
    for (const auto& name : heldInWindow) buffers.buffers.erase(name);
  }
  // Once denoised: the window takes the buffers it holds (heldInBuffers), or
  // they are dropped where it has its copies already. The copies taken, to
  // be packed where no bit changes (WindowImage::packIfExact).
  std::vector<WindowImage*> holdInWindow() {
    std::vector<WindowImage*> taken;
    if (!std::exchange(heldInBuffers, false)) {
      dropHeld();
      return taken;
    }
    const auto copies = windowCopies();
    for (std::size_t k = 0; k < copies.size(); ++k) {
      auto held = buffers.buffers.find(kHeldInWindow[k]);
      if (!heldInWindow.count(kHeldInWindow[k]) || held == buffers.buffers.end()) continue;
      *copies[k] = std::move(held->second);
      taken.push_back(copies[k]);
      buffers.buffers.erase(held);
    }
    return taken;
  }
};

namespace {

// The albedo, normal and depth of a frame file: the guides of reprojection.
// Taken from the buffers and the extra channels read (one decoding of the
// file less), else read.
motion::Guides guidesOf(const FrameBuffers& frame, const std::string& path,
                        const ReadOptions& base) {
  ReadOptions read = base;
  read.only = {"color"};
  const bool depthRead = frame.extra.count("depth") != 0;
  for (const auto& b : availableBuffers(path, base))
    if ((b == "albedo" || b == "normal" || (b == "depth" && !depthRead)) && !frame.has(b))
      read.only.push_back(b);
  const FrameBuffers extra = read.only.size() > 1 ? readFrame(path, read) : FrameBuffers();
  auto guide = [&](const std::string& name) {
    return frame.has(name) ? frame.get(name) : extra.has(name) ? extra.get(name) : Image();
  };
  motion::Guides g;
  g.albedo = guide("albedo");
  g.normal = guide("normal");
  g.depth = depthRead ? frame.extra.at("depth") : guide("depth");
  return g;
}

// Whether the frame's first denoising cleaned its albedo and normal (the
// prefilter mode): then they replace the file's guides.
bool guidesCleaned(const WindowImage& cleanAlbedo, const WindowImage& cleanNormal) {
  return !cleanAlbedo.empty() && !cleanNormal.empty();
}

// The frame's buffers that withCleanedGuides replaces, and so need not be read again.
std::set<std::string> cleanedGuideNames(const WindowImage& cleanAlbedo,
                                        const WindowImage& cleanNormal) {
  if (!guidesCleaned(cleanAlbedo, cleanNormal)) return {};
  return {"albedo", "normal"};
}

// The frame with its albedo and normal replaced by the prefilter's where its
// first denoising cleaned them.
FrameBuffers withCleanedGuides(FrameBuffers out, const WindowImage& cleanAlbedo,
                               const WindowImage& cleanNormal) {
  if (guidesCleaned(cleanAlbedo, cleanNormal)) {
    out.buffers["albedo"] = cleanAlbedo.toImage();
    out.buffers["normal"] = cleanNormal.toImage();
    out.auxPrefiltered = true;
  }
  return out;
}

// The same, its colour replaced by the accumulated render, whose noise is
// the frame's: steered as the frame's first denoising chose (`alone`).
FrameBuffers withHistory(FrameBuffers out, Image history, const DenoiseResult& alone,
                         const WindowImage& cleanAlbedo, const WindowImage& cleanNormal) {
  out.buffers["color"] = std::move(history);
  out.accumulated = true;
  out.correlatedNoise = alone.steered;
  return withCleanedGuides(std::move(out), cleanAlbedo, cleanNormal);
}

// "WxH".
std::string sizeText(const WindowImage& image) {
  return std::to_string(image.width()) + "x" + std::to_string(image.height());
}

// FrameBuffers::extra's names of the motion channels' groups (MotionChannels::groups).
const char* const kMotionGroups[] = {"motion", "motion (second group)"};

bool allZero(const Image* image) {
  return !image ||
         std::all_of(image->pixels.begin(), image->pixels.end(), [](float v) { return v == 0.0f; });
}

// The taps of the past neighbours whose histories a companion's history is
// averaged with: those of window frames `frames` (the colour's past
// histories) but a relit one. Brought to the frame's light by a box ratio, a
// relit history cost the light passes of a tuning shot whose lamp's pool
// moves (SPLIT_1080.md's lantern_shed) 0.11 dB in Diffuse Direct and 0.14 in
// Glossy Direct, by its own ratio or its pass alone's; left out, they lose
// nothing anywhere on the tuning half.
FilterWeights pastHistoryTaps(FilterWeights weights, const std::vector<std::size_t>& frames) {
  auto& n = weights.neighbours;
  n.erase(std::remove_if(n.begin(), n.end(),
                         [&](const NeighbourWeights& nb) {
                           return nb.relit ||
                                  std::find(frames.begin(), frames.end(), nb.frame) == frames.end();
                         }),
          n.end());
  return weights;
}

template <class Map>
void keepWithin(Map& frames, int first, int last) {
  for (auto it = frames.begin(); it != frames.end();)
    it = (it->first < first || it->first > last) ? frames.erase(it) : std::next(it);
}

}  // namespace

Sequence::Sequence(std::string pattern, std::map<std::string, int> numbers,
                   SequenceSettings settings)
    : pattern_(std::move(pattern)), numbers_(std::move(numbers)), settings_(std::move(settings)) {}

std::unique_ptr<Sequence> Sequence::plan(const std::string& pattern,
                                         const std::vector<std::string>& files,
                                         const SequenceSettings& settings, std::string& why) {
  why.clear();
  if (files.empty()) return nullptr;
  std::map<std::string, int> numbers;
  for (const auto& file : files)
    if (auto n = frameNumberOf(pattern, file)) numbers[file] = *n;
  if (numbers.size() != files.size()) return nullptr;
  const std::string& first = files.front();
  if (!settings.motion.empty()) {
    if (!isFramePattern(settings.motion))
      throw std::invalid_argument("--motion " + settings.motion +
                                  ": a sequence needs a motion pattern");
  } else if (!motion::findMotionChannels(channelNames(first), settings.read.viewLayer)) {
    why = first +
          ": no motion vectors (Blender: the Vector pass, motion blur off; or --motion FILES); "
          "denoising frame by frame";
    return nullptr;
  }
  return std::unique_ptr<Sequence>(new Sequence(pattern, std::move(numbers), settings));
}

std::string Sequence::fileOf(int number) const {
  const std::string path = frameFile(pattern_, number);
  std::error_code ec;
  return fs::exists(path, ec) ? path : std::string();
}

ChannelGroups Sequence::extraChannels(const std::string& path) const {
  ChannelGroups buffers = bufferChannels(path, settings_.read);
  ChannelGroups extra;
  if (buffers.count("depth")) extra["depth"] = buffers.at("depth");
  if (settings_.motion.empty())
    if (auto found = motion::findMotionChannels(channelNames(path), settings_.read.viewLayer)) {
      const auto groups = found->groups();
      for (std::size_t k = 0; k < groups.size(); ++k) extra[kMotionGroups[k]] = groups[k];
    }
  if (settings_.viewDependentShare && settings_.viewDependentChannels)
    extra.merge(settings_.viewDependentChannels(path, layerPrefixOf(buffers["color"])));
  return extra;
}

std::optional<motion::MotionField> Sequence::motionOf(int number, const std::string& path,
                                                      const FrameBuffers& frame) const {
  if (!settings_.motion.empty())
    return motion::readMotion(frameFile(settings_.motion, number), frame.width, frame.height, "",
                              true);
  if (frame.extra.count(kMotionGroups[0])) {
    const auto found = motion::findMotionChannels(channelNames(path), settings_.read.viewLayer);
    std::vector<Image> read = {frame.extra.at(kMotionGroups[0])};
    if (frame.extra.count(kMotionGroups[1])) read.push_back(frame.extra.at(kMotionGroups[1]));
    if (found && found->groups().size() == read.size())
      return motion::decodeMotion(*found, read, frame.width, frame.height, path);
  }
  return motion::readMotion(path, frame.width, frame.height, settings_.read.viewLayer);
}

FrameBuffers Sequence::Input::readAgain(const std::set<std::string>& replaced) const {
  FrameBuffers out = buffers;
  out.alpha = alpha.toImage();
  if (heldInBuffers) return out;
  const auto copies = windowCopies();
  for (std::size_t k = 0; k < copies.size(); ++k)
    if (heldInWindow.count(kHeldInWindow[k]) && !replaced.count(kHeldInWindow[k]))
      out.buffers.emplace(kHeldInWindow[k], copies[k]->toImage());
  return out;
}

std::shared_ptr<Sequence::Input> Sequence::input(int number, const FrameBuffers* given,
                                                 const Read& read) {
  if (auto it = inputs_.find(number); it != inputs_.end()) return it->second;
  const std::string path = fileOf(number);
  if (path.empty()) return nullptr;
  auto entry = std::make_shared<Input>();
  // A given frame is denoised straight from the caller's buffers.
  if (!given) entry->buffers = read(path, extraChannels(path));
  const FrameBuffers& frame = given ? *given : entry->buffers;
  // The view-dependent share is made on a thread of its own while the guides
  // and motion are taken.
  std::future<Image> viewDependent;
  if (settings_.viewDependentShare)
    viewDependent =
        std::async(settings_.filter.threads > 1 ? std::launch::async : std::launch::deferred,
                   [&] { return settings_.viewDependentShare(path, frame); });
  entry->frame.noisy = frame.get("color");
  entry->frame.guides = guidesOf(frame, path, settings_.read);
  if (auto field = motionOf(number, path, frame)) entry->frame.motion = std::move(*field);
  // The motion packed, the copies only where no bit changes (Sequence::frame
  // gives them back), each image on a thread of the filter's.
  const auto copies = entry->windowCopies();
  std::array<bool, std::size(kHeldInWindow)> asRead{};
  std::vector<std::function<void()>> packs = {[&] { entry->frame.motion.toPrevious.pack(); },
                                              [&] { entry->frame.motion.toNext.pack(); }};
  for (std::size_t k = 0; k < copies.size(); ++k)
    packs.push_back([&, k] {
      const char* name = kHeldInWindow[k];
      asRead[k] = frame.has(name) && frame.get(name).pixels == copies[k]->floats().pixels;
      copies[k]->packIfExact();
    });
  forEach(packs.size(), settings_.filter.threads, [&](std::size_t t) { packs[t](); });
  for (std::size_t k = 0; k < copies.size(); ++k)
    if (asRead[k]) entry->heldInWindow.insert(kHeldInWindow[k]);
  if (viewDependent.valid()) entry->frame.viewDependent = viewDependent.get();
  entry->frame.viewDependent.pack();
  if (given) {  // kept for Sequence::frame, but for what the window holds
    entry->buffers = *given;
    entry->dropHeld();
  } else {  // the network reads the buffers first
    for (std::size_t k = 0; k < copies.size(); ++k)
      if (entry->heldInWindow.count(kHeldInWindow[k])) *copies[k] = WindowImage();
    entry->heldInBuffers = true;
  }
  entry->alpha = std::move(entry->buffers.alpha);
  entry->alpha.packIfExact();
  entry->buffers.alpha = Image();
  entry->buffers.extra.clear();
  inputs_[number] = entry;
  return entry;
}

FrameBuffers Sequence::frame(const std::string& file, const Read& read) {
  const auto number = numbers_.find(file);
  if (number == numbers_.end())
    throw std::invalid_argument(file + ": not one of the sequence's frames");
  const auto held = input(number->second, nullptr, read);
  if (!held) throw std::invalid_argument(file + ": no such file");
  return held->readAgain();
}

std::shared_ptr<const DenoiseResult> Sequence::estimate(int number, const FrameBuffers* given,
                                                        const Read& read, const Denoise& denoise) {
  if (auto it = estimates_.find(number); it != estimates_.end()) return it->second;
  auto self = input(number, given, read);
  if (!self) return nullptr;
  auto result =
      std::make_shared<DenoiseResult>(denoise(fileOf(number), given ? *given : self->buffers));
  // The filter's input, held once, in half floats: the window holds it from
  // the frame ahead that is denoised first to the frame behind dropped last.
  self->frame.denoised = std::move(result->color);
  self->cleanAlbedo = std::move(result->cleanAlbedo);
  self->cleanNormal = std::move(result->cleanNormal);
  // Each image packed on a thread of the filter's: the buffers the window
  // takes where no bit changes, its results rounded. Once cleaned, no network
  // of the sequence reads the file's normal again (withHistory gives the
  // clean one): it is a guide, rounded too.
  struct Pack {
    WindowImage* image;
    bool exact, rounded;
  };
  std::vector<Pack> packs;
  for (WindowImage* taken : self->holdInWindow()) packs.push_back({taken, true, false});
  for (WindowImage* made : {&self->frame.denoised, &self->cleanAlbedo, &self->cleanNormal})
    packs.push_back({made, false, true});
  if (!self->cleanNormal.empty() && !settings_.framesAsRead) {
    WindowImage* normal = &self->frame.guides.normal;
    auto taken =
        std::find_if(packs.begin(), packs.end(), [&](const Pack& p) { return p.image == normal; });
    if (taken != packs.end())
      taken->rounded = true;
    else
      packs.push_back({normal, false, true});
  }
  forEach(packs.size(), settings_.filter.threads, [&](std::size_t k) {
    if (packs[k].exact) packs[k].image->packIfExact();
    if (packs[k].rounded) packs[k].image->pack();
  });
  return estimates_[number] = result;
}

Sequence::Span Sequence::windowOf(int number) const {
  const int radius = settings_.radius;
  auto filesOn = [&](int side) {  // up to 2 radius, a missing file ends the side
    int k = 0;
    while (k < 2 * radius && !fileOf(number + side * (k + 1)).empty()) ++k;
    return k;
  };
  const int past = filesOn(-1), future = filesOn(1);
  return {number - std::min(past, 2 * radius - std::min(future, radius)),
          number + std::min(future, 2 * radius - std::min(past, radius))};
}

void Sequence::forget(int number) {
  // Memory stays bounded by the window: what lies outside it is dropped.
  const Span window = windowOf(number);
  keepWithin(inputs_, window.first, window.last);
  keepWithin(estimates_, window.first, window.last);
}

Sequence::Filtered Sequence::filtered(int number, const FrameBuffers* given, const Read& read,
                                      const Denoise& denoise) {
  const Span span = windowOf(number);
  Filtered out;
  out.alone = estimate(number, given, read, denoise);
  if (!out.alone) return out;
  const WindowImage& own = input(number, nullptr, read)->frame.denoised;
  std::vector<const WindowFrame*> window;
  std::vector<const DeviceFrame*> deviceWindow;
  for (int m = span.first; m <= span.last; ++m) {
    // Whichever call made them, the filter sees the past frames so (a shot
    // split into runs gives the same bits); held so before the later frames
    // are denoised.
    if (m == number)
      for (int p = span.first; p < number; ++p)
        if (auto past = inputs_.find(p); past != inputs_.end())
          past->second->enterPast(settings_.filterDevice);
    auto source = estimate(m, nullptr, read, denoise) ? input(m, nullptr, read) : nullptr;
    const bool usable = source && source->frame.denoised.sameShape(own);
    if (source && m != number) {
      ++out.present;
      if (!usable && out.otherSize++ == 0) out.otherSizeName = sizeText(source->frame.denoised);
    }
    window.push_back(usable ? &source->frame : nullptr);
    if (settings_.filterDevice) deviceWindow.push_back(usable ? &onDevice(*source) : nullptr);
  }
  TemporalOptions options = settings_.filter;
  const auto centre = static_cast<std::size_t>(number - span.first);
  options.radius = std::max(number - span.first, span.last - number);
  if (!settings_.filterDevice) {
    out.result = filterFrame(window, centre, options);
    return out;
  }
  out.device = filterFrame(deviceWindow, centre, options);
  out.result.stats = out.device->stats;
  if (out.device->history.defined())  // the network's input
    out.result.history = pixelsToImage(out.device->history, own.width(), own.height());
  return out;
}

const DeviceFrame& Sequence::onDevice(Input& input) const {
  if (!input.onDevice) input.onDevice = toDevice(input.frame, *settings_.filterDevice);
  return *input.onDevice;
}

Image Sequence::blendOnDevice(int number, const DeviceTemporalResult& filtered,
                              double share) const {
  const DeviceFrame& self = *inputs_.at(number)->onDevice;
  torch::Tensor color = filtered.color;
  if (share > 0.0)
    color = blendWithHistory(color, historyMean(self.history, filtered, settings_.filter), share);
  return pixelsToImage(color, self.width, self.height);
}

Image Sequence::denoisedHistory(int number, const FrameBuffers* given, TemporalResult& filtered,
                                const Denoise& denoise) {
  Input& self = *inputs_.at(number);
  // Where no neighbour was trusted the history is the frame's own render.
  // withHistory replaces its colour, and its guides where cleaned: those are
  // not unpacked.
  std::set<std::string> replaced = cleanedGuideNames(self.cleanAlbedo, self.cleanNormal);
  replaced.insert("color");
  Image history =
      denoisesAgain(filtered.stats)
          ? denoise(fileOf(number), withHistory(given ? *given : self.readAgain(replaced),
                                                std::move(filtered.history), *estimates_.at(number),
                                                self.cleanAlbedo, self.cleanNormal))
                .color
          : self.frame.denoised.toImage();
  if (self.onDevice)
    self.onDevice->history = denoisesAgain(filtered.stats)
                                 ? pixelsToDevice(history, *settings_.filterDevice)
                                 : self.onDevice->denoised;
  self.frame.history = history;  // the later frames' past history, in half floats
  self.frame.history.pack();
  return history;
}

void Sequence::makePastHistories(int number, const Read& read, const Denoise& denoise,
                                 const CompanionMaker& companions) {
  const bool again = companions.make && companions.denoiseAccumulated;
  for (int m = windowOf(number).first; m < number; ++m) {
    auto past = input(m, nullptr, read);
    if (!past) continue;
    const bool colour = past->frame.history.empty();
    if (!colour && !(again && !past->companionHistories)) continue;
    forget(m);  // its window only, so memory stays bounded at a run's start too
    Filtered earlier = filtered(m, nullptr, read, denoise);
    if (!earlier.alone) continue;
    if (again) {
      const FilterWeights weights =
          earlier.device ? earlier.device->weights.toHost() : std::move(earlier.result.weights);
      companionHistories(
          m, nullptr,
          filteredCompanions(m, weights, companions, denoisesAgain(earlier.result.stats)),
          companions);
    }
    earlier.result.weights = FilterWeights();
    if (colour) denoisedHistory(m, nullptr, earlier.result, denoise);
  }
}

const Sequence::HeldCompanions& Sequence::companionsOf(int number, const CompanionMaker& make) {
  Input& entry = *inputs_.at(number);
  if (!entry.companions) {
    entry.companions.emplace();
    for (auto& [name, made] : make.make(fileOf(number), entry.readAgain())) {
      HeldCompanion& held = (*entry.companions)[name];
      held.image = std::move(made.image);
      held.render = std::move(made.render);
      held.overTime = made.overTime, held.viewDependent = made.viewDependent;
      held.render.packIfExact();
      if (held.overTime)
        held.image.pack();  // as the colour's result is
      else if (entry.inPast)
        held.image = WindowImage();  // only the frame filtered reads it
    }
  }
  return *entry.companions;
}

Sequence::FilteredCompanions Sequence::filteredCompanions(int number, const FilterWeights& weights,
                                                          const CompanionMaker& make,
                                                          bool accumulate) {
  // Window index k is frame number - centre + k; only the frames the colour
  // took something from are needed.
  const int first = number - static_cast<int>(weights.centre);
  std::map<std::size_t, const HeldCompanions*> made;
  made[weights.centre] = &companionsOf(number, make);
  for (const NeighbourWeights& nb : weights.neighbours)
    made[nb.frame] = &companionsOf(first + static_cast<int>(nb.frame), make);
  const std::size_t size = made.rbegin()->first + 1;
  const HeldCompanions& ownCompanions = *made.at(weights.centre);
  std::vector<const std::string*> overTime;
  FilteredCompanions out;
  for (const auto& [name, own] : ownCompanions)
    if (own.overTime)
      overTime.push_back(&name);
    else
      out.filtered[name] = own.image.toImage();
  // A view-dependent pass's share alone per pixel, by the frame's view-dependent
  // share of its light, where its file has such passes.
  const TemporalOptions& o = settings_.filter;
  const WindowImage& viewDependent = inputs_.at(number)->frame.viewDependent;
  const Image viewDependentShareAlone = accumulate && !viewDependent.empty()
                                            ? viewDependentAlone(viewDependent.toImage(), o)
                                            : Image();
  // Each pass on a thread of the filter's: they share nothing but the weights.
  struct Pass {
    Image filtered, accumulated, historyShare;
  };
  std::vector<Pass> passes(overTime.size());
  forEach(overTime.size(), settings_.filter.threads, [&](std::size_t p) {
    const std::string& name = *overTime[p];
    const HeldCompanion& own = ownCompanions.at(name);
    Pass& pass = passes[p];
    // In floats while this companion is filtered.
    std::vector<Image> unpacked(2 * size);
    std::vector<const Image*> images(size, nullptr), renders(size, nullptr);
    for (const auto& [index, companions] : made) {
      auto it = companions->find(name);
      if (it == companions->end()) continue;
      images[index] = &it->second.image.floats(unpacked[index]);
      if (!it->second.render.empty())
        renders[index] = &it->second.render.floats(unpacked[size + index]);
    }
    // A pass no frame of the window has (Cycles writes transmission black
    // where nothing transmits) stays black, without resampling.
    if (std::all_of(images.begin(), images.end(), [](const Image* i) { return allZero(i); }) &&
        std::all_of(renders.begin(), renders.end(), [](const Image* i) { return allZero(i); })) {
      pass.filtered = *images[weights.centre];
      return;
    }
    // A view-dependent pass takes the colour's weights as they are: they already
    // fall with motion by the frame's view-dependent share of the light.
    const TestedWeights tested = own.viewDependent || own.render.empty()
                                     ? TestedWeights()
                                     : passLightTested(weights, renders, images, o);
    pass.filtered = filterWith(weights, images, 0.0, &tested);
    if (accumulate && !own.render.empty()) {
      Image frames;
      pass.accumulated = accumulateWith(weights, renders, images, 0.0, &frames, &tested);
      pass.historyShare =
          own.viewDependent && !viewDependentShareAlone.empty()
              ? passHistoryShare(frames, viewDependentShareAlone, o)
              : passHistoryShare(
                    frames, own.viewDependent ? o.viewDependentShareAlone : o.lightShareAlone, o);
    }
  });
  for (std::size_t p = 0; p < overTime.size(); ++p) {
    const std::string& name = *overTime[p];
    out.filtered[name] = std::move(passes[p].filtered);
    if (passes[p].accumulated.empty()) continue;
    out.accumulated[name] = std::move(passes[p].accumulated);
    out.historyShare[name] = std::move(passes[p].historyShare);
  }
  return out;
}

std::map<std::string, Image> Sequence::companionHistories(int number, const FrameBuffers* given,
                                                          const FilteredCompanions& passes,
                                                          const CompanionMaker& make) {
  Input& input = *inputs_.at(number);
  std::map<std::string, Image> again;
  if (!passes.accumulated.empty()) {
    const FrameBuffers guides = withCleanedGuides(
        given ? *given : input.readAgain(cleanedGuideNames(input.cleanAlbedo, input.cleanNormal)),
        input.cleanAlbedo, input.cleanNormal);
    again = make.denoiseAccumulated(guides, passes.accumulated);
  }
  // Where nothing was accumulated the history is the companion itself, as
  // the colour's is its result.
  for (auto& [name, held] : *input.companions) {
    if (held.render.empty()) continue;
    auto it = again.find(name);
    held.history = it != again.end() ? WindowImage(it->second) : held.image;
    held.history.pack();
  }
  input.companionHistories = true;
  return again;
}

Image Sequence::companionHistoryMean(int number, const std::string& name, const Image& own,
                                     const FilterWeights& weights) const {
  if (weights.empty()) return own;
  const int first = number - static_cast<int>(weights.centre);
  std::vector<const Image*> histories(weights.centre + 1, nullptr);
  std::vector<Image> unpacked(histories.size());
  histories[weights.centre] = &own;
  for (const NeighbourWeights& nb : weights.neighbours) {
    const auto& companions = inputs_.at(first + static_cast<int>(nb.frame))->companions;
    if (!companions || !companions->count(name)) continue;
    const WindowImage& history = companions->at(name).history;
    if (!history.empty()) histories[nb.frame] = &history.floats(unpacked[nb.frame]);
  }
  return filterWith(weights, histories);
}

DenoiseResult Sequence::denoise(const std::string& file, const FrameBuffers& frame,
                                const Read& read, const Denoise& denoise) {
  return denoiseFrame(file, &frame, read, denoise, CompanionMaker()).result;
}

Sequence::WithCompanions Sequence::denoise(const std::string& file, const FrameBuffers& frame,
                                           const Read& read, const Denoise& denoise,
                                           const CompanionMaker& companions) {
  return denoiseFrame(file, &frame, read, denoise, companions);
}

DenoiseResult Sequence::denoise(const std::string& file, const Read& read, const Denoise& denoise) {
  return denoiseFrame(file, nullptr, read, denoise, CompanionMaker()).result;
}

Sequence::WithCompanions Sequence::denoise(const std::string& file, const Read& read,
                                           const Denoise& denoise,
                                           const CompanionMaker& companions) {
  return denoiseFrame(file, nullptr, read, denoise, companions);
}

Sequence::WithCompanions Sequence::denoiseFrame(const std::string& file, const FrameBuffers* given,
                                                const Read& read, const Denoise& denoise,
                                                const CompanionMaker& companions) {
  const int n = numbers_.at(file);
  forget(n);
  lastNumber_ = n;
  const double share = settings_.filter.accumulatedShare;
  // The past frames' histories: made by the calls before, or here for the
  // first frames of a run (a shot split into runs gives the same bits).
  if (share > 0.0) makePastHistories(n, read, denoise, companions);
  for (auto& [number, past] : inputs_)
    if (number < n) past->dropOwnUse();
  Filtered self = filtered(n, given, read, denoise);
  lastStats_ = self.result.stats;
  lastAloneBecause_ = aloneBecause(*inputs_.at(n), self);
  WithCompanions out{*self.alone, {}};
  // The companions first, so that the neighbours' taps and weights are gone
  // before the networks run again (about 21 bytes a pixel a neighbour), but
  // for the past ones with a history where the companions are denoised again.
  FilteredCompanions passes;
  FilterWeights pastTaps;
  const bool again = share > 0.0 && companions.make && companions.denoiseAccumulated;
  if (companions.make) {
    FilterWeights weights =
        self.device ? self.device->weights.toHost() : std::move(self.result.weights);
    passes = filteredCompanions(n, weights, companions, again && denoisesAgain(self.result.stats));
    if (again)
      pastTaps =
          pastHistoryTaps(std::move(weights), self.device ? self.device->pastHistories.frames
                                                          : self.result.pastHistories.frames);
  }
  self.result.weights = FilterWeights();
  DenoiseResult& result = out.result;
  FilterWeights pastHistories;  // the colour's history weights, for the companions'
  if (self.device) {
    self.device->weights = DeviceFilterWeights();
    if (share > 0.0) denoisedHistory(n, given, self.result, denoise);
    if (again)
      pastHistories = historyWeights(inputs_.at(n)->onDevice->history, *self.device, pastTaps,
                                     settings_.filter);
    result.color = blendOnDevice(n, *self.device, share);
  } else {
    result.color = std::move(self.result.color);
    if (share > 0.0) {
      const Image own = denoisedHistory(n, given, self.result, denoise);
      result.color =
          blendWithHistory(result.color, historyMean(own, self.result, settings_.filter), share);
      if (again) pastHistories = historyWeights(own, self.result, pastTaps, settings_.filter);
    }
  }
  pastTaps = FilterWeights();
  if (again)
    for (const auto& [name, own] : companionHistories(n, given, passes, companions)) {
      Image& pass = passes.filtered.at(name);
      const Image history = companionHistoryMean(n, name, own, pastHistories);
      pass = blendWithHistory(pass, history, passes.historyShare.at(name));
    }
  out.companions = std::move(passes.filtered);
  return out;
}

DenoiseResult Sequence::denoise(const std::string& file, const Denoiser& denoiser,
                                const DenoiseOptions& options) {
  const Read read = [&](const std::string& path, const ChannelGroups& extra) {
    ReadOptions only = settings_.read;
    only.only = denoiser.buffersToRead(availableBuffers(path, only), options);
    only.extra = extra;
    return readFrame(path, only);
  };
  const Denoise alone = [&](const std::string&, const FrameBuffers& frame) {
    return denoiser.denoise(frame, options);
  };
  return denoise(file, read, alone);
}

std::string Sequence::report() const {
  const TemporalStats& s = lastStats_;
  char line[400];
  int n =
      std::snprintf(line, sizeof line, "frame %d: %.0f%% from history (%d neighbour%s", lastNumber_,
                    100 * s.historyShare, s.neighbours, s.neighbours == 1 ? "" : "s");
  auto add = [&](const char* format, int count) {
    if (count > 0 && n >= 0 && n < int(sizeof line))
      n += std::snprintf(line + n, sizeof line - n, format, count);
  };
  add(", %d repeating its noise and left out", s.repeatedNoise);
  add(", %d brought to its light first", s.relit);
  add(", %d brought to it where its light drifted", s.drifted);
  add(", %d with the light changed over the frame and left out", s.changedLight);
  std::string out = std::string(line) + ")";
  if (settings_.filter.accumulatedShare > 0.0 && denoisesAgain(s)) {
    std::snprintf(line, sizeof line, "; its render accumulated over %.1f frames, denoised again",
                  s.accumulatedFrames);
    out += line;
  }
  return out;
}

std::string Sequence::aloneBecause() const { return lastAloneBecause_; }

std::string Sequence::aloneBecause(const Input& input, const Filtered& filtered) {
  if (input.frame.motion.empty())
    return "no motion vectors in this frame (Blender: the Vector pass, motion blur off): "
           "denoised alone, and its neighbours' chains stop at it";
  if (filtered.present > 0 && filtered.otherSize == filtered.present) {
    return "this frame is " + sizeText(input.frame.denoised) + ", its neighbours " +
           filtered.otherSizeName + ": denoised alone, and their chains stop at it";
  }
  return std::string();
}

}  // namespace dn::temporal
