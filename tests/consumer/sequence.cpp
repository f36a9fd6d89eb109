// sequence PATTERN FRAMES OUT_PATTERN: denoises the frames FRAMES (e.g. 1-3)
// of a shot with motion vectors through the installed dn::temporal (with
// dn::denoise's view-dependent share of the light passes), each frame
// filtered with its neighbours' results and their noisy renders accumulated and
// denoised again (the defaults), and writes each result as float RGB
// to OUT_PATTERN. Prints "frame N history H neighbours K" per frame.
#include <cstdio>
#include <exception>
#include <string>
#include <vector>

#include "dn/infer/denoiser.h"
#include "dn/io/buffer_io.h"
#include "dn/io/frame_pattern.h"
#include "dn/passes/sequence_passes.h"
#include "dn/temporal/sequence.h"

int main(int argc, char** argv) {
  if (argc != 4) {
    std::fputs("usage: sequence PATTERN FRAMES OUT_PATTERN\n", stderr);
    return 1;
  }
  try {
    const std::string pattern = argv[1], output = argv[3];
    const dn::Denoiser denoiser =
        dn::Denoiser::fromFile(std::string(DN_MODEL_DIR) + "/default.dnm");
    std::vector<std::string> files;
    std::vector<int> numbers;
    for (const auto& [number, file] : dn::patternFrames(pattern, argv[2]).present)
      files.push_back(file), numbers.push_back(number);
    // As dndenoise: light that moves with the view (the glossy and
    // transmission passes' share) taken only where the surface stood still.
    dn::temporal::SequenceSettings settings;
    settings.viewDependentShare = [](const std::string& path, const dn::FrameBuffers& frame) {
      return dn::viewDependentShare(path, frame);
    };
    std::string why;
    auto shot = dn::temporal::Sequence::plan(pattern, files, settings, why);
    if (!shot) {
      std::fprintf(stderr, "sequence: %s\n", why.empty() ? "not a sequence" : why.c_str());
      return 1;
    }
    const dn::DenoiseOptions options;
    for (std::size_t i = 0; i < files.size(); ++i) {
      const dn::DenoiseResult result = shot->denoise(files[i], denoiser, options);
      dn::writeImage(dn::frameFile(output, numbers[i]), result.color, false, {"R", "G", "B"});
      std::printf("frame %d history %.6g neighbours %d\n", shot->lastFrame(),
                  shot->lastStats().historyShare, shot->lastStats().neighbours);
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "sequence: %s\n", e.what());
    return 1;
  }
  return 0;
}
