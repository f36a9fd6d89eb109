// The temporal filter of `dndenoise --temporal filter`, run over frames already
// denoised alone (`dndenoise --temporal off --float`), so that its settings
// can be measured in seconds instead of re-denoising every frame. The same
// code path as dndenoise (dn/temporal/sequence.h), with the "denoiser"
// reading the frame's stored result.
//   temporal_refilter NOISY.#.exr ALONE.#.exr -o OUT.#.exr [--window N]
//                     [--colour LOW,HIGH] [--light-spread S] [--drift BOX,THRESHOLD]
//                     [--frames RANGE]
//                     [--trust FILE] [--dump-trust DIR --target TARGET.#.exr]
// --trust: a learned trust (LearnedTrust::toText) in place of the rules.
// --dump-trust: per frame N, what the learned trust sees and the independent
// render TARGET of the frame, as .npy for experiments/temporal_trust/fit.py:
// DIR/NNNN.own.npy (H,W,3), .target.npy (H,W,3), .moved.npy (K,H,W,3),
// .features.npy (K,H,W,F), .weights.npy (K,H,W: the filter's), .scale.npy (1).
#include <fmt/format.h>

#include <cstdio>
#include <filesystem>
#include <string>
#include <thread>

#include "common/cli.h"
#include "common/sequence.h"
#include "dn/io/frame_pattern.h"
#include "dn/io/npy.h"
#include "dn/passes/sequence_passes.h"
#include "dn/temporal/sequence.h"

using namespace dn;

namespace {

// Images of one shape stacked as (K, H, W, C).
std::vector<float> stackedPixels(const std::vector<Image>& images) {
  std::vector<float> out;
  for (const Image& image : images) out.insert(out.end(), image.pixels.begin(), image.pixels.end());
  return out;
}

template <class T>
std::vector<float> stackedValues(const std::vector<std::vector<T>>& values) {
  std::vector<float> out;
  for (const auto& v : values) out.insert(out.end(), v.begin(), v.end());
  return out;
}

void dumpTrust(const std::string& prefix, const temporal::TrustSamples& s, const Image& target) {
  const int64_t k = static_cast<int64_t>(s.moved.size()), h = s.own.height, w = s.own.width;
  npy::writeImage(prefix + ".own.npy", s.own);
  npy::writeImage(prefix + ".target.npy", target);
  npy::write(prefix + ".moved.npy", {k, h, w, 3}, stackedPixels(s.moved));
  npy::write(prefix + ".features.npy", {k, h, w, temporal::kTrustFeatureCount},
             stackedValues(s.features));
  npy::write(prefix + ".weights.npy", {k, h, w}, stackedValues(s.weights));
  npy::write(prefix + ".scale.npy", {1}, {static_cast<float>(s.scale)});
}

}  // namespace

int main(int argc, char** argv) {
  try {
    cli::Args args(argc, argv);
    std::vector<std::string> positional;
    std::string output, frames, dumpDir, target;
    temporal::SequenceSettings settings;
    settings.filter.threads = static_cast<int>(std::thread::hardware_concurrency());
    // The results are read, not denoised: the filter alone (dndenoise --temporal filter).
    settings.filter.accumulatedShare = 0.0;
    settings.viewDependentShare = [](const std::string& path, const FrameBuffers& frame) {
      return viewDependentShare(path, frame);
    };
    settings.viewDependentChannels = [](const std::string& path, const std::string& prefix) {
      return viewDependentChannels(path, prefix);
    };
    while (!args.done()) {
      if (args.flag("-o")) {
        output = args.value("-o");
      } else if (args.flag("--window")) {
        settings.radius = args.intValue("--window", 1, 8);
      } else if (args.flag("--colour")) {
        const auto values = cli::splitList(args.value("--colour"));
        if (values.size() != 2) throw cli::UsageError("--colour LOW,HIGH");
        settings.filter.colourLow = cli::Args::toDouble("--colour", values[0]);
        settings.filter.colourHigh = cli::Args::toDouble("--colour", values[1]);
      } else if (args.flag("--drift")) {
        const auto values = cli::splitList(args.value("--drift"));
        if (values.size() != 2) throw cli::UsageError("--drift BOX,THRESHOLD");
        settings.filter.driftBox = static_cast<int>(cli::Args::toDouble("--drift", values[0]));
        settings.filter.driftThreshold = cli::Args::toDouble("--drift", values[1]);
      } else if (args.flag("--light-spread")) {
        settings.filter.changedLightSpread = args.doubleValue("--light-spread", 0.0, 1e9);
      } else if (args.flag("--frames")) {
        frames = args.value("--frames");
      } else if (args.flag("--trust")) {
        settings.filter.learnedTrust = std::make_shared<const temporal::LearnedTrust>(
            temporal::LearnedTrust::fromFile(args.value("--trust")));
      } else if (args.flag("--dump-trust")) {
        dumpDir = args.value("--dump-trust");
      } else if (args.flag("--target")) {
        target = args.value("--target");
      } else {
        positional.push_back(args.positional());
      }
    }
    if (positional.size() != 2 || output.empty())
      throw cli::UsageError("usage: temporal_refilter NOISY.#.exr ALONE.#.exr -o OUT.#.exr");
    const std::string noisy = positional[0], alone = positional[1];
    if (!dumpDir.empty() && target.empty()) throw cli::UsageError("--dump-trust needs --target");
    std::vector<std::string> inputs;
    std::vector<int> numbers;
    for (const auto& [n, path] : cli::sequenceFrames(noisy, frames, false, "temporal_refilter"))
      inputs.push_back(path), numbers.push_back(n);
    // The filter runs once a frame here (no accumulated history): the frame's own.
    int dumpNumber = 0;
    if (!dumpDir.empty()) {
      std::filesystem::create_directories(dumpDir);
      settings.filter.observeTrust = [&](const temporal::TrustSamples& s) {
        ReadOptions only;
        only.only = {"color"};
        dumpTrust(fmt::format("{}/{:04d}", dumpDir, dumpNumber), s,
                  readFrame(frameFile(target, dumpNumber), only).buffers.at("color"));
      };
    }
    std::string why;
    auto sequence = temporal::Sequence::plan(noisy, inputs, settings, why);
    if (!sequence) throw IoError(noisy + ": " + (why.empty() ? "not a sequence" : why));
    const temporal::Sequence::Read read = [](const std::string& path, const ChannelGroups& extra) {
      ReadOptions only;
      only.only = {"color"};
      only.extra = extra;
      return readFrame(path, only);
    };
    const temporal::Sequence::Denoise stored = [&](const std::string& path, const FrameBuffers&) {
      DenoiseResult result;
      result.color = readImage(frameFile(alone, *frameNumberOf(noisy, path)), 3);
      return result;
    };
    for (std::size_t i = 0; i < inputs.size(); ++i) {
      dumpNumber = numbers[i];
      const DenoiseResult result = sequence->denoise(inputs[i], read(inputs[i], {}), read, stored);
      writeImage(frameFile(output, numbers[i]), result.color, false, {"R", "G", "B"});
      fmt::print(stderr, "temporal_refilter: {}: {}\n", inputs[i], sequence->report());
    }
    return 0;
  } catch (const std::exception& e) {
    fmt::print(stderr, "temporal_refilter: {}\n", e.what());
    return 1;
  }
}
