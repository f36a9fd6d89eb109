// What dndenoise prints about each frame: the input's statistics (-v), the
// buffers used, the noise the base left, the method and times (-v or -n), the
// light passes (-v), and the --ref check.
#pragma once

#include <string>
#include <vector>

#include "dn/infer/denoiser.h"
#include "dn/passes/joint_denoise.h"
#include "dn/passes/sequence_passes.h"
#include "dndenoise/options.h"

namespace dn::dndenoise {

// Counts what the model will not see as radiance: NaN/Inf and negative values.
void reportInputStatistics(const std::string& name, const Image& color);

// -v: the buffers the network saw and those it ignored, and the noise the base
// left; -v or -n: the method and the median of `times`. `input` is the
// frame's file (empty: separate buffer files).
void reportResult(const Options& o, const Denoiser& denoiser, const std::string& name,
                  const std::string& input, const FrameBuffers& frame, const DenoiseResult& result,
                  std::vector<double> times);

// -v: the light passes found, the rule and how closely the denoised ones recombine.
// `overTime`: a sequence's passes' options, where they are filtered over time.
void reportPasses(const std::string& name, const PassesResult& passes,
                  const SequencePassOptions* overTime);

// --ref/--maxerror: one line; `status` becomes kExitThreshold when it fails.
void checkAgainstReference(const Options& o, const Image& ref, const Image& result, int& status);

}  // namespace dn::dndenoise
