// Turns loader batches into trainer batches, and makes the base prior's
// pretraining pairs: clean images (rendered ground truths, photographs) and a
// degraded copy to condition on, as DeepFloyd IF stage II is conditioned on a
// low-resolution image.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <torch/torch.h>

#include "dn/data/dataset.h"
#include "dn/tonemap.h"
#include "dn/train/trainer.h"

namespace dn {

// Loader batch (linear HDR, planar) -> tonemapped noisy/target and normalized aux.
TrainBatch toTrainBatch(const data::Batch& batch, const std::vector<std::string>& auxBuffers,
                        tonemap::Curve curve);

// Planar linear-HDR tensors of a loader batch.
torch::Tensor colorTensor(const data::Batch& batch);
torch::Tensor targetTensor(const data::Batch& batch);
torch::Tensor auxTensor(const data::Batch& batch);  // unnormalized

// Photographs as clean HDR-ish training images: decoded from sRGB to linear,
// random crops, flips and exposures (so highlights exceed 1 as in renders).
class PhotoSource {
 public:
  // Every image file (jpg, png, exr) under the folders; throws IoError if none.
  explicit PhotoSource(const std::vector<std::string>& folders, int64_t maxSide = 1024);
  // (B,3,crop,crop) linear radiance drawn with `generator`.
  torch::Tensor draw(int64_t batch, int64_t crop, torch::Generator& generator) const;
  std::size_t size() const { return photos_.size(); }

 private:
  std::vector<torch::Tensor> photos_;  // (3,H,W) linear
};

// A degraded copy of clean linear radiance (B,3,H,W): a random mix of
// down/upsampling, blur, and Monte Carlo-like noise (heavy-tailed multiplicative
// noise with sparse fireflies), each strength drawn per image.
torch::Tensor degrade(const torch::Tensor& clean, torch::Generator& generator);

}  // namespace dn
