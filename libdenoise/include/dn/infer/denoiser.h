// The library's front door: a model file plus one frame's buffers in, a
// denoised HDR image out. The model file says which pipeline runs: the default
// over OIDN's pretrained networks (dn/infer/oidn_pipeline.h), or the
// from-scratch diffusion model kept as an experiment
// (dn/infer/scratch_diffusion.h).
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "dn/infer/denoise_options.h"
#include "dn/infer/pipeline.h"
#include "dn/io/buffers.h"
#include "dn/nn/model_file.h"
#include "dn/nn/model_inputs.h"  // imageToTensor, tensorToImage

namespace dn {

class Denoiser {
 public:
  explicit Denoiser(LoadedModel model);
  static Denoiser fromFile(const std::string& path);  // throws ModelError

  const ModelInfo& info() const { return model_.info; }
  // Whether the model runs the default pipeline over OIDN's networks (false:
  // the from-scratch diffusion experiment).
  bool overOidnBase() const { return model_.info.base_kind == BaseKind::Oidn; }
  // OIDN's networks the default pipeline runs (null for the from-scratch model),
  // for callers that run them on other buffers, e.g. the light passes.
  OidnBase oidnBase() const { return model_.oidn; }
  // Buffers the model needs that are not among `available` (empty: ready to
  // denoise); `available` as FrameBuffers::names() or dn::availableBuffers give it.
  std::vector<std::string> missingBuffers(const std::vector<std::string>& available) const;
  // The buffers the model would use from `available`, colour first.
  std::vector<std::string> usableBuffers(const std::vector<std::string>& available) const;
  // Those of usableBuffers to read before denoising with `options`: a path that
  // needs more reads it then from FrameBuffers::unread.
  std::vector<std::string> buffersToRead(const std::vector<std::string>& available,
                                         const DenoiseOptions& options) const;
  // Whether a Control Module steers the base on a render with these buffers
  // (it needs its base network's inputs; its extra buffers may be missing).
  bool controlApplies(const std::vector<std::string>& available) const;
  // Estimated activation bytes per pixel of one network evaluation (for tiling).
  double bytesPerPixel() const { return pipeline_->bytesPerPixel(); }

  // Throws std::invalid_argument when buffers are missing (see missingBuffers)
  // or an option is out of range.
  DenoiseResult denoise(const FrameBuffers& frame, const DenoiseOptions& options) const;

  // The frame's Monte Carlo noise in the model's tonemapped space at `exposure`
  // (0: the model's autoexposure), as the from-scratch model's sampling plan uses it.
  double measureNoise(const FrameBuffers& frame, double exposure = 0.0) const;

 private:
  LoadedModel model_;
  std::shared_ptr<const Pipeline> pipeline_;
};

}  // namespace dn
