// The temporal filter of `dndenoise --temporal filter`, run over frames already
// denoised alone (`dndenoise --temporal off --float`), so that its settings
// can be measured in seconds instead of re-denoising every frame. The same
// code path as dndenoise (dn/temporal/sequence.h), with the "denoiser"
// reading the frame's stored result.
//   temporal_refilter NOISY.#.exr ALONE.#.exr -o OUT.#.exr [--window N]
//                     [--colour LOW,HIGH] [--light-spread S] [--frames RANGE]
#include <fmt/format.h>

#include <cstdio>
#include <string>
#include <thread>

#include "common/cli.h"
#include "common/sequence.h"
#include "dn/io/frame_pattern.h"
#include "dn/temporal/sequence.h"

using namespace dn;

int main(int argc, char** argv) {
  try {
    cli::Args args(argc, argv);
    std::vector<std::string> positional;
    std::string output, frames;
    temporal::SequenceSettings settings;
    settings.filter.threads = static_cast<int>(std::thread::hardware_concurrency());
    // The results are read, not denoised: the filter alone (dndenoise --temporal filter).
    settings.filter.accumulatedShare = 0.0;
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
      } else if (args.flag("--light-spread")) {
        settings.filter.changedLightSpread = args.doubleValue("--light-spread", 0.0, 1e9);
      } else if (args.flag("--frames")) {
        frames = args.value("--frames");
      } else {
        positional.push_back(args.positional());
      }
    }
    if (positional.size() != 2 || output.empty())
      throw cli::UsageError("usage: temporal_refilter NOISY.#.exr ALONE.#.exr -o OUT.#.exr");
    const std::string noisy = positional[0], alone = positional[1];
    std::vector<std::string> inputs;
    std::vector<int> numbers;
    for (const auto& [n, path] : cli::sequenceFrames(noisy, frames, false, "temporal_refilter"))
      inputs.push_back(path), numbers.push_back(n);
    std::string why;
    auto sequence = temporal::Sequence::plan(noisy, inputs, settings, why);
    if (!sequence) throw IoError(noisy + ": " + (why.empty() ? "not a sequence" : why));
    const temporal::Sequence::Read read = [](const std::string& path) {
      ReadOptions only;
      only.only = {"color"};
      return readFrame(path, only);
    };
    const temporal::Sequence::Denoise stored = [&](const std::string& path, const FrameBuffers&) {
      DenoiseResult result;
      result.color = readImage(frameFile(alone, *frameNumberOf(noisy, path)), 3);
      return result;
    };
    for (std::size_t i = 0; i < inputs.size(); ++i) {
      const DenoiseResult result = sequence->denoise(inputs[i], read(inputs[i]), read, stored);
      writeImage(frameFile(output, numbers[i]), result.color, false, {"R", "G", "B"});
      fmt::print(stderr, "temporal_refilter: {}: {}\n", inputs[i], sequence->report());
    }
    return 0;
  } catch (const std::exception& e) {
    fmt::print(stderr, "temporal_refilter: {}\n", e.what());
    return 1;
  }
}
