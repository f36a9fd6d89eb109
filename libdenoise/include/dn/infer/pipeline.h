// What the Denoiser runs for one kind of model: the default pipeline over the
// OIDN base (dn/infer/oidn_pipeline.h), or an experiment behind the same calls.
#pragma once

#include <string>
#include <vector>

#include "dn/infer/denoise_options.h"
#include "dn/io/buffers.h"

namespace dn {

class Pipeline {
 public:
  virtual ~Pipeline() = default;
  // Buffers it needs that are not among `available` (empty: ready to denoise).
  virtual std::vector<std::string> missingBuffers(
      const std::vector<std::string>& available) const = 0;
  // The buffers it would read from `available`, colour first.
  virtual std::vector<std::string> usableBuffers(
      const std::vector<std::string>& available) const = 0;
  // Those of usableBuffers to read before denoising with `options`; the others
  // are read when a path needs them (FrameBuffers::unread).
  virtual std::vector<std::string> buffersToRead(const std::vector<std::string>& available,
                                                 const DenoiseOptions&) const {
    return usableBuffers(available);
  }
  // Estimated activation bytes per pixel of one network evaluation (for tiling).
  virtual double bytesPerPixel() const = 0;
  // The frame has every buffer it needs; options are checked here.
  virtual DenoiseResult denoise(const FrameBuffers& frame, const DenoiseOptions& options) const = 0;
};

}  // namespace dn
