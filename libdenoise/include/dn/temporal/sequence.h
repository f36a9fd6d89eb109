// Denoising a frame sequence with motion vectors: every frame denoised alone,
// then filtered over time with its neighbours' results brought in along the
// motion where they are trusted (dn/temporal/temporal_filter.h). A frame's
// result depends only on the input frames within the window (read from disk
// beyond the frames asked for), never on how the shot was split into runs.
//
//   dn::Denoiser denoiser = dn::Denoiser::fromFile("default.dnm");
//   std::vector<std::string> files;  // e.g. from dn::patternFrames("shot.#.exr")
//   std::string why;
//   auto shot = dn::temporal::Sequence::plan("shot.#.exr", files, {}, why);
//   for (const auto& file : files)  // shot is nullptr without motion vectors
//     dn::writeImage(out, shot->denoise(file, denoiser, options).color, ...);
#pragma once

#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "dn/infer/denoiser.h"
#include "dn/io/buffer_io.h"
#include "dn/temporal/device_filter.h"
#include "dn/temporal/temporal_filter.h"

namespace dn::temporal {

struct SequenceSettings {
  // Neighbours on each side; where a side has fewer (a shot's first and last
  // frames), as many more on the other, up to twice this.
  int radius = 4;
  std::string motion;      // motion vectors from separate files: a pattern (mv.#.exr)
  ReadOptions read;        // the view layer and channel overrides
  TemporalOptions filter;  // the rejection thresholds (its radius: each frame's window)
  // Where set, a frame's WindowFrame::viewDependent, from its file and its
  // buffers as Read gives them (empty where the file cannot tell); dndenoise
  // sets dn::viewDependentShare (dn/passes/sequence_passes.h).
  std::function<Image(const std::string& path, const FrameBuffers& frame)> viewDependentShare;
  // Where set, the channels viewDependentShare reads of a frame's file (by the
  // colour's layer prefix), asked of Read with the buffers (ReadOptions::extra),
  // so that each file is decoded once (dn::viewDependentChannels).
  std::function<ChannelGroups(const std::string& path, const std::string& layerPrefix)>
      viewDependentChannels;
  // Unset: the filter runs on the CPU (temporal_filter.h; its output does not
  // change). Set: as tensor operations on this device (device_filter.h), each
  // frame copied there once and kept while in the window, the colour copied
  // back once filtered and blended. dndenoise sets it with --device cuda.
  std::optional<torch::Device> filterDevice;
  // Set where the caller denoises a frame's buffers (Sequence::frame) again as
  // read (dndenoise --passes-temporal off): the window then holds the file's
  // normal bit for bit even once the prefilter has cleaned it (12 MB more a
  // 1080p frame).
  bool framesAsRead = false;
};

// An image made per frame beside its colour (a renderer's light pass,
// denoised alone), filtered over the window with the colour's weights.
struct Companion {
  Image image;           // the frame's size, any channel count
  bool overTime = true;  // false: kept as made
  // Light that moves with the view (a glossy pass): it takes the colour's
  // weights as they are (they fall with motion by the frame's view-dependent
  // share), no light test of its own, and its own share alone of its second
  // denoising (TemporalOptions::viewDependentShareAlone).
  bool viewDependent = false;
  // The image as rendered, where it is denoised again once accumulated as
  // the colour's render is (CompanionMaker::denoiseAccumulated); else empty.
  Image render;
};
using Companions = std::map<std::string, Companion>;

// How each frame's companions are made and, where they carry their render,
// their accumulated renders denoised.
struct CompanionMaker {
  // A frame's companions, from its file and its buffers as Sequence's Read gives them.
  std::function<Companions(const std::string& path, const FrameBuffers& frame)> make;
  // The companions' accumulated renders (by name) denoised, with `guides`:
  // the frame's albedo and normal, cleaned where guides.auxPrefiltered. Each
  // result is then blended with its filtered companion by
  // TemporalOptions::accumulatedShare, as the colour is. Unset: filtered only.
  std::function<std::map<std::string, Image>(const FrameBuffers& guides,
                                             const std::map<std::string, Image>& accumulated)>
      denoiseAccumulated;
};

class Sequence {
 public:
  // Reads a frame's buffers, and in the same decoding the channel groups
  // `extra` into FrameBuffers::extra (ReadOptions::extra).
  using Read = std::function<FrameBuffers(const std::string& path, const ChannelGroups& extra)>;
  // Denoises `frame`, which is the frame of file `path`.
  using Denoise = std::function<DenoiseResult(const std::string& path, const FrameBuffers& frame)>;

  // The plan for the frames `files` of `pattern` ("shot.#.exr"), or nullptr:
  // no files, a file not of the pattern, or no motion vectors (then `why`
  // says in one line that it denoises frame by frame). Throws
  // std::invalid_argument when settings.motion is given but not a pattern.
  static std::unique_ptr<Sequence> plan(const std::string& pattern,
                                        const std::vector<std::string>& files,
                                        const SequenceSettings& settings, std::string& why);

  // The result of `file` (one of the planned files; `frame` as `read` gives
  // it): denoised alone, its colour then filtered with the neighbours' results.
  // Neighbours are read and denoised here as needed and kept while in the window.
  DenoiseResult denoise(const std::string& file, const FrameBuffers& frame, const Read& read,
                        const Denoise& denoise);

  // The same, and the frame's companions by name, each filtered over the
  // window with the colour's weights (the same neighbours, taps and per-pixel
  // weights; dn::temporal::filterWith), or as made where not overTime; those
  // with a render also blended with their accumulated render denoised,
  // averaged with the past frames' as the colour's is (historyWeights). Each
  // frame's are made once, by `companions.make`, for the frames the colour
  // took something from, and kept while the frame is in the window.
  struct WithCompanions {
    DenoiseResult result;
    std::map<std::string, Image> companions;
  };
  WithCompanions denoise(const std::string& file, const FrameBuffers& frame, const Read& read,
                         const Denoise& denoise, const CompanionMaker& companions);
  // The same, the frame put back together from the window (Sequence::frame)
  // only where needed: the caller holds no copy of it while the networks run
  // (76 MB of a 1080p frame's colour, albedo and normal in floats).
  DenoiseResult denoise(const std::string& file, const Read& read, const Denoise& denoise);
  WithCompanions denoise(const std::string& file, const Read& read, const Denoise& denoise,
                         const CompanionMaker& companions);
  // The same with `denoiser`: each frame read with the buffers it needs.
  DenoiseResult denoise(const std::string& file, const Denoiser& denoiser,
                        const DenoiseOptions& options);

  // The buffers of `file` (one of the planned files) as `read` gives them:
  // put back together from what the window holds where it holds the frame,
  // else read (and then held), so that each file is decoded once. Once the
  // frame is denoised with its albedo and normal cleaned (the prefilter), its
  // normal is a guide only, held in half floats, unless
  // SequenceSettings::framesAsRead. Throws std::invalid_argument for a file
  // not planned, or gone.
  FrameBuffers frame(const std::string& file, const Read& read);

  // What the sequence asks Read for beside the buffers of file `path`: the
  // depth guide, the motion vectors, the view-dependent passes.
  ChannelGroups extraChannels(const std::string& path) const;

  // How much of the last frame came from history.
  const TemporalStats& lastStats() const { return lastStats_; }
  int lastFrame() const { return lastNumber_; }
  // The same in one line: "frame N: 40% from history (4 neighbours...)".
  std::string report() const;
  // Why the last frame was denoised alone, in one line, where its file is the
  // reason: it has no motion vectors, or its size is not its neighbours'
  // (their chains then stop at it too); else empty.
  std::string aloneBecause() const;

 private:
  struct Input;
  Sequence(std::string pattern, std::map<std::string, int> numbers, SequenceSettings settings);
  std::shared_ptr<Input> input(int number, const FrameBuffers* given, const Read& read);
  // Frame `number`'s motion (file `path`, read as `frame`): from its extra
  // channels where read there, else read.
  std::optional<motion::MotionField> motionOf(int number, const std::string& path,
                                              const FrameBuffers& frame) const;
  // A frame's own estimate: denoised alone.
  std::shared_ptr<const DenoiseResult> estimate(int number, const FrameBuffers* given,
                                                const Read& read, const Denoise& denoise);
  // The frame's result alone and filtered over its window (alone: null where
  // the frame's file is missing).
  struct Filtered {
    std::shared_ptr<const DenoiseResult> alone;
    // On the device: only the stats and the accumulated render (for the
    // network) are on the host; the rest is in `device`.
    TemporalResult result;
    std::optional<DeviceTemporalResult> device;
    // The window's frames left out for being of another size than the frame:
    // how many, of how many present, and the first one's size.
    int otherSize = 0, present = 0;
    std::string otherSizeName;  // "WxH"
  };
  Filtered filtered(int number, const FrameBuffers* given, const Read& read,
                    const Denoise& denoise);
  // The denoise calls above: `given`, the caller's copy of the frame, or null.
  WithCompanions denoiseFrame(const std::string& file, const FrameBuffers* given, const Read& read,
                              const Denoise& denoise, const CompanionMaker& companions);
  // The frame's accumulated render (of `filtered`) denoised, kept for its
  // successors; the frame `given`, else as the window holds it.
  Image denoisedHistory(int number, const FrameBuffers* given, TemporalResult& filtered,
                        const Denoise& denoise);
  // Makes the denoised histories of the frames within the window before `number`
  // that lack one, their companions' too where `companions` denoises them again.
  void makePastHistories(int number, const Read& read, const Denoise& denoise,
                         const CompanionMaker& companions);
  // A companion as the window holds it: its render in half floats where the
  // file had it so, its image and its history (its accumulated render
  // denoised, else its image) in half floats, as the colour's; one kept as
  // made in floats, until the frame is in the past.
  struct HeldCompanion {
    WindowImage image, render, history;
    bool overTime = true, viewDependent = false;
  };
  using HeldCompanions = std::map<std::string, HeldCompanion>;
  // Frame `number`'s companions, made by `make` from the frame as the window
  // holds it (Sequence::frame), if not yet.
  const HeldCompanions& companionsOf(int number, const CompanionMaker& make);
  // The companions filtered over the window, and those with a render
  // accumulated (by name).
  struct FilteredCompanions {
    std::map<std::string, Image> filtered, accumulated;
    std::map<std::string, Image> historyShare;  // per pixel, of those accumulated
  };
  FilteredCompanions filteredCompanions(int number, const FilterWeights& weights,
                                        const CompanionMaker& make, bool accumulate);
  // The companions' accumulated renders (of filteredCompanions) denoised again
  // (guided by the frame `given`, else as the window holds it), each kept as
  // the companion's history for the later frames, with those of the
  // companions that have a render but were not accumulated.
  std::map<std::string, Image> companionHistories(int number, const FrameBuffers* given,
                                                  const FilteredCompanions& passes,
                                                  const CompanionMaker& make);
  // A companion's history averaged with the past frames' (historyWeights).
  Image companionHistoryMean(int number, const std::string& name, const Image& own,
                             const FilterWeights& weights) const;
  // The frame on settings_.filterDevice, copied there on first use.
  const DeviceFrame& onDevice(Input& input) const;
  // The filtered colour blended with the accumulated render denoised (and
  // averaged with the past frames'), on the device; the result copied back.
  Image blendOnDevice(int number, const DeviceTemporalResult& filtered, double share) const;
  std::string fileOf(int number) const;
  // The frames filtered with frame `number`, its own included: settings_.radius
  // on each side, and where a side has fewer files (a shot's ends), as many
  // more on the other, so that every frame of a shot is filtered over as
  // many frames as its middle ones.
  struct Span {
    int first, last;
  };
  Span windowOf(int number) const;
  // Drops what lies outside frame `number`'s window.
  void forget(int number);
  // aloneBecause() of the frame held as `input`, filtered as `filtered`.
  static std::string aloneBecause(const Input& input, const Filtered& filtered);
  // Whether a frame's accumulated render (and its light passes') is denoised
  // again: wherever it took anything from its neighbours. Even a frame that
  // took little gains from it (docs/RESULTS.md, "Where the second denoising pays").
  static bool denoisesAgain(const TemporalStats& stats) { return stats.accumulatedFrames > 1.0; }

  std::string pattern_;
  std::map<std::string, int> numbers_;  // input file -> frame number
  SequenceSettings settings_;
  std::map<int, std::shared_ptr<Input>> inputs_;
  std::map<int, std::shared_ptr<const DenoiseResult>> estimates_;
  TemporalStats lastStats_;
  int lastNumber_ = 0;
  std::string lastAloneBecause_;
};

}  // namespace dn::temporal
