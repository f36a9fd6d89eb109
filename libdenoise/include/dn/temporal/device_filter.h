// The temporal filter (temporal_filter.h) as LibTorch tensor operations, so
// that one code path runs on the CPU and on CUDA, and a shot's frames stay on
// the device while they are in the window. The same algorithm and options as
// filterFrame: reprojection chained along the motion, the guides' tests with
// their neighbourhood, Catmull-Rom with the bilinear fallback, the repeated
// noise, light and colour tests, relighting, the learned trust, the light
// that moves with the view, the weighted mean, the accumulated render and the
// past frames' histories.
//
// It computes in float32 where filterFrame computes in double, and its sums
// run in another order, so its results differ from filterFrame's in the last
// bits (tests/test_temporal_device.cpp states by how much); the guides' tests
// compare with their thresholds in double, as reproject.cpp does, so the taps
// are the same. Where no neighbour is trusted both give the frame's own
// result exactly. Whole-frame decisions (a neighbour's spread, its noise
// correlation) come back to the host once per neighbour; every per-pixel step
// stays on the device, and runs the same from run to run there (no atomics).
#pragma once

#include <torch/torch.h>

#include <cstddef>
#include <vector>

#include "dn/image.h"
#include "dn/temporal/temporal_filter.h"

namespace dn::temporal {

// One frame of the window on a device. Images are (channels, height x width)
// float tensors; a missing guide, motion or history is an undefined tensor.
struct DeviceFrame {
  int width = 0, height = 0;
  torch::Tensor denoised, noisy;  // 3 channels
  torch::Tensor history;          // 3 channels, once made (WindowFrame::history)
  torch::Tensor albedo, normal, depth;
  torch::Tensor toPrevious, toNext;  // 2 channels each
  torch::Tensor viewDependent;       // 1 channel (WindowFrame::viewDependent)
  bool hasMotion() const { return toPrevious.defined() && toNext.defined(); }
};

// The frame's images copied to `device`.
DeviceFrame toDevice(const WindowFrame& frame, const torch::Device& device);
// An interleaved image as a (channels, pixels) tensor on `device`, and back.
torch::Tensor pixelsToDevice(const Image& image, const torch::Device& device);
Image pixelsToImage(const torch::Tensor& pixels, int width, int height);

// reproject.h's Resampling on the device: the taps use its bits.
struct DeviceResampling {
  torch::Tensor positions;  // 2 channels: where each pixel is in the neighbour; NaN: lost
  torch::Tensor taps;       // uint8 per pixel, Resampling::taps' bits
  torch::Tensor trust;      // float per pixel
  motion::Resampling toHost(int width, int height) const;
};

struct DeviceNeighbourWeights {
  std::size_t frame = 0;  // its index in the window
  DeviceResampling resampling;
  bool relit = false;
  torch::Tensor drifted;  // bool per pixel (NeighbourWeights::drifted); undefined: nowhere
  torch::Tensor weight;   // float per pixel, after every test
};

// FilterWeights on the device: filterWith on tensors, or toHost for the
// CPU's filterWith (a light pass denoised on the host).
struct DeviceFilterWeights {
  std::size_t centre = 0;
  int relightBox = 1;
  double relightRange = 10.0;
  int driftBox = 31;
  int width = 0, height = 0;
  std::vector<DeviceNeighbourWeights> neighbours;
  bool empty() const { return neighbours.empty(); }
  FilterWeights toHost() const;
};

struct DevicePastHistories {
  std::vector<torch::Tensor> images, weights;
  std::vector<std::size_t> frames;  // per image: its frame's index in the window
  torch::Tensor scale;              // the frame's autoexposure (a 0-d tensor)
  torch::Tensor noise;              // its render's local noise level per pixel
  bool empty() const { return images.empty(); }
};

struct DeviceTemporalResult {
  int width = 0, height = 0;
  torch::Tensor color;  // 3 channels
  DeviceFilterWeights weights;
  torch::Tensor history, historyFrames;  // undefined where accumulatedShare is 0
  DevicePastHistories pastHistories;
  TemporalStats stats;
};

// filterFrame on the window's frames on one device; options.threads is not
// used. Throws std::invalid_argument as filterFrame does.
DeviceTemporalResult filterFrame(const std::vector<const DeviceFrame*>& window, std::size_t centre,
                                 const TemporalOptions& options = {});

// filterWith on (channels, pixels) tensors of the window's frames (with
// `stillPixels` as there).
torch::Tensor filterWith(const DeviceFilterWeights& weights,
                         const std::vector<const torch::Tensor*>& images, double stillPixels = 0.0);

// historyMean and blendWithHistory on the device.
torch::Tensor historyMean(const torch::Tensor& own, const DeviceTemporalResult& result,
                          const TemporalOptions& options = {});
torch::Tensor blendWithHistory(const torch::Tensor& filtered, const torch::Tensor& accumulated,
                               double share);
// historyWeights (temporal_filter.h) of a result on the device, on the host.
FilterWeights historyWeights(const torch::Tensor& own, const DeviceTemporalResult& result,
                             const FilterWeights& taps, const TemporalOptions& options = {});

// The result's images and stats on the host, as filterFrame gives them; its
// weights too where `withWeights` (they cost a copy of every neighbour's).
TemporalResult toHost(const DeviceTemporalResult& result, bool withWeights);

}  // namespace dn::temporal
