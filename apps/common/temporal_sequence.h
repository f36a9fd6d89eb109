// dndenoise on a frame sequence with motion vectors: every frame denoised
// alone, then filtered over time with its neighbours' results brought in along
// the motion where they are trusted (dn/temporal/temporal_filter.h). A frame's
// result depends only on the input frames within the window (read from disk
// beyond the frames asked for), never on how the shot was split into runs.
#pragma once

#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "dn/infer/denoiser.h"
#include "dn/io/buffer_io.h"
#include "dn/temporal/temporal_filter.h"

namespace dn::cli {

struct TemporalSettings {
  // --temporal on|off: on wherever the frames carry motion vectors.
  bool enabled = true;
  int radius = 4;                    // --window N: neighbours on each side
  std::string motion;                // --motion FILE or PATTERN: separate motion files
  ReadOptions read;                  // the view layer and channel overrides
  temporal::TemporalOptions filter;  // the rejection thresholds (its radius is `radius`)
};

// The frame number of `path` in `pattern` ("shot.#.exr"), or nullopt.
std::optional<int> frameNumberOf(const std::string& pattern, const std::string& path);

class TemporalSequence {
 public:
  using Read = std::function<FrameBuffers(const std::string& path)>;
  // Denoises `frame`, which is the frame of file `path`.
  using Denoise = std::function<DenoiseResult(const std::string& path, const FrameBuffers& frame)>;

  // The temporal plan for `inputs` (the tool's input arguments) whose frames
  // are `jobInputs`, or nullptr: turned off, not one sequence, or no motion
  // vectors (then `why` says in one line that it denoises frame by frame).
  static std::unique_ptr<TemporalSequence> plan(const std::vector<std::string>& inputs,
                                                const std::vector<std::string>& jobInputs,
                                                const TemporalSettings& settings, std::string& why);

  // The result of `input` (a frame of the sequence; `frame` as `read` gives
  // it): denoised alone, its colour then filtered with the neighbours' results.
  // Neighbours are read and denoised here as needed and kept while in the window.
  DenoiseResult denoise(const std::string& input, const FrameBuffers& frame, const Read& read,
                        const Denoise& denoise);

  // One line for -v: how much of the last frame came from history.
  std::string report() const;

 private:
  struct Input;
  TemporalSequence(std::string pattern, std::map<std::string, int> numbers,
                   TemporalSettings settings);
  std::shared_ptr<Input> input(int number, const FrameBuffers* given, const Read& read);
  // A frame's own estimate: denoised alone.
  std::shared_ptr<const DenoiseResult> estimate(int number, const FrameBuffers* given,
                                                const Read& read, const Denoise& denoise);
  std::string fileOf(int number) const;
  void forget(int number);

  std::string pattern_;
  std::map<std::string, int> numbers_;  // input file -> frame number
  TemporalSettings settings_;
  std::map<int, std::shared_ptr<Input>> inputs_;
  std::map<int, std::shared_ptr<const DenoiseResult>> estimates_;
  temporal::TemporalStats lastStats_;
  int lastNumber_ = 0;
};

}  // namespace dn::cli
