// Where dndenoise's result goes: a multilayer EXR beside the input's layers
// and metadata (with the uncertainty and the denoised light passes), a plain
// RGB image, or a display picture; and the --preview picture.
#pragma once

#include <optional>
#include <string>

#include "dn/infer/denoiser.h"
#include "dn/ocio_preview.h"
#include "dn/passes/joint_denoise.h"
#include "dndenoise/options.h"

namespace dn::dndenoise {

struct Written {
  std::string output;   // the result's file
  std::string preview;  // its --preview picture, or empty
  std::string input;    // the input file (empty: separate buffer files, named by `name`)
  std::string name;
};

// Writes `result` of `frame` (and the passes, when given) to `files`, then
// names them with -v.
void writeOutputs(const Options& o, const Written& files, const FrameBuffers& frame,
                  const DenoiseResult& result, const std::optional<PassesResult>& passes,
                  const std::optional<tonemap::OcioDisplay>& display);

}  // namespace dn::dndenoise
