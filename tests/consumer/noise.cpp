// noise RENDER.exr REFERENCE.exr: loads the installed default model with
// dn::denoise, and measures the Monte Carlo noise of the render's colour and of
// the converged reference's colour with the render's feature buffers.
// Prints "buffers a,b,..." (what the model reads), "noisy V" and "converged V".
#include <cstdio>
#include <exception>
#include <string>

#include "dn/infer/denoiser.h"
#include "dn/io/buffer_io.h"

int main(int argc, char** argv) {
  if (argc != 3) {
    std::fputs("usage: noise RENDER.exr REFERENCE.exr\n", stderr);
    return 1;
  }
  try {
    const dn::Denoiser denoiser =
        dn::Denoiser::fromFile(std::string(DN_MODEL_DIR) + "/default.dnm");
    dn::FrameBuffers frame = dn::readFrame(argv[1]);
    if (!denoiser.missingBuffers(frame.names()).empty()) {
      std::fprintf(stderr, "noise: %s lacks buffers the model needs\n", argv[1]);
      return 1;
    }
    std::string buffers;
    for (const auto& b : denoiser.info().input_buffers) buffers += (buffers.empty() ? "" : ",") + b;
    std::printf("buffers %s\n", buffers.c_str());
    std::printf("noisy %.6g\n", denoiser.measureNoise(frame));
    frame.buffers["color"] = dn::readImage(argv[2], 3);
    std::printf("converged %.6g\n", denoiser.measureNoise(frame));
  } catch (const std::exception& e) {
    std::fprintf(stderr, "noise: %s\n", e.what());
    return 1;
  }
  return 0;
}
