// The default pipeline: OIDN's networks (the frozen pretrained base) on the
// frame's colour, albedo and normal, read top to bottom in oidn_pipeline.cpp:
//   1. pick the base network for the buffers at hand (colour, + albedo, + normal);
//   2. prefilter: albedo and normal denoised by their own networks, the colour
//      by the large network for clean aux (OIDN's prefilter mode);
//   3. light paths: the diffuse part and the rest denoised apart and averaged
//      with the whole (dn/infer/light_paths.h);
//   4. gate: how much noise the base left; correlated noise (a pixel filter
//      that splats samples) hands the frame to the Control Module;
//   5. Control Module: steers the base with the buffers OIDN ignores, with
//      diffusion refinement where the model has it.
#pragma once

#include <string>
#include <vector>

#include "dn/infer/oidn_filter.h"
#include "dn/infer/pipeline.h"
#include "dn/nn/model_file.h"
#include "dn/nn/oidn_control.h"
#include "dn/nn/oidn_unet.h"

namespace dn {

// The frame's colour with its albedo and normal denoised by the base's own
// networks: the inputs of the prefilter mode's colour network.
FrameBuffers withCleanAux(const OidnBase& base, const FrameBuffers& frame,
                          const OidnRunOptions& albedoRun, const OidnRunOptions& normalRun);

// Steps 2 and 3: the prefilter mode, with the light-path split when asked;
// the cleaned albedo and normal go to `clean` where given.
OidnRunResult runOidnPrefiltered(const OidnBase& base, const FrameBuffers& frame,
                                 const OidnRunOptions& options, bool splitLightPaths,
                                 FrameBuffers* clean = nullptr);

// The base's inner convolutions in `precision` for the runs that follow
// (OidnUNetImpl::useInnerPrecision); each caller of the networks sets its own.
void useNetworkPrecision(const OidnBase& base, Precision precision);

class OidnPipeline : public Pipeline {
 public:
  // `controlled` is null for a model without a Control Module.
  OidnPipeline(const ModelInfo& info, OidnBase base, OidnControlled controlled);

  std::vector<std::string> missingBuffers(const std::vector<std::string>& available) const override;
  std::vector<std::string> usableBuffers(const std::vector<std::string>& available) const override;
  // The base network's buffers, the gate's depth, the diffuse passes with the
  // split; the Control Module's extras only when it steers whatever the gate says.
  std::vector<std::string> buffersToRead(const std::vector<std::string>& available,
                                         const DenoiseOptions& options) const override;
  double bytesPerPixel() const override;
  DenoiseResult denoise(const FrameBuffers& frame, const DenoiseOptions& options) const override;

  // Whether the Control Module can steer on a render with these buffers (it
  // needs its base network's inputs; its extra buffers may be missing).
  bool controlApplies(const std::vector<std::string>& available) const;

 private:
  // `gate`: the noise the base left is measured (DenoiseResult::noiseLeft).
  DenoiseResult denoiseWithBase(const FrameBuffers& frame, const DenoiseOptions& options,
                                bool gate) const;
  DenoiseResult denoiseWithControl(const FrameBuffers& frame, const DenoiseOptions& options) const;

  ModelInfo info_;
  OidnBase base_;
  OidnControlled controlled_;
};

}  // namespace dn
