// A frame's buffers on the run's device, each sent on first use and kept for
// the rest of the frame: the prefilter mode's networks and the gate read the
// same copies, so no buffer crosses to a GPU twice in a frame (the gate's
// second upload of the colour and the features was 13 ms of the default's 52
// at 1080p on an H200).
#pragma once

#include <map>
#include <string>

#include <torch/torch.h>

#include "dn/io/buffers.h"

namespace dn {

class FrameUploads {
 public:
  // `frame` must outlive this.
  FrameUploads(const FrameBuffers& frame, torch::Device device);

  // The buffer as stored, (1, C, H, W) float on the device: imageToDevice's
  // values, sent the first time it is asked for.
  const torch::Tensor& stored(const std::string& name);
  // Whether these are `frame`'s buffers (not those of a frame made from it,
  // such as one with cleaned aux or transposed parts).
  bool holds(const FrameBuffers& frame) const { return &frame == frame_; }
  const FrameBuffers& frame() const { return *frame_; }
  torch::Device device() const { return device_; }

 private:
  const FrameBuffers* frame_;
  torch::Device device_;
  std::map<std::string, torch::Tensor> sent_;
};

}  // namespace dn
