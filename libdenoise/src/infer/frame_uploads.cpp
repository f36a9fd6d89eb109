#include "dn/infer/frame_uploads.h"

#include "dn/nn/model_inputs.h"

namespace dn {

FrameUploads::FrameUploads(const FrameBuffers& frame, torch::Device device)
    : frame_(&frame), device_(device) {}

const torch::Tensor& FrameUploads::stored(const std::string& name) {
  auto it = sent_.find(name);
  if (it == sent_.end()) it = sent_.emplace(name, imageToDevice(frame_->get(name), device_)).first;
  return it->second;
}

}  // namespace dn
