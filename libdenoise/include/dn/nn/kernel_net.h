// A kernel-predicting network in the style of Isik et al. 2021 ("Interactive
// Monte Carlo Denoising using Affinity of Neural Features"), without temporal
// terms: a small UNet turns the radiance and auxiliary buffers into per-pixel
// feature vectors, bandwidths and centre weights; affinities between a pixel's
// features and its neighbours' give normalised k x k kernels at growing
// dilations, applied one after the other to the linear radiance.
//
// Used as the ground-truth cleanser C(F, GT1) -> GT2 (Noise2Noise, SMAPE loss)
// and, trained on low-spp inputs, as the paper's "Isik" baseline denoiser.
//
// The kernels filter linear HDR radiance, not the tonemapped image: every output
// is a convex combination of input pixels, so local means of radiance are kept
// (averaging in the log domain would darken noisy regions) and values above the
// model range (lights, highlights) pass through instead of being clipped.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <torch/torch.h>

#include "dn/image.h"
#include "dn/io/buffers.h"
#include "dn/tonemap.h"

namespace dn {

// Keeps demodulation finite where the albedo is 0 (black surfaces, emitters, sky).
constexpr double kDemodulationEps = 0.02;

struct KernelNetConfig {
  std::vector<std::string> input_buffers;      // canonical aux buffer names, in order
  std::string tonemap = "log";                 // radiance curve for the feature network inputs
  std::vector<int64_t> widths = {24, 32, 48};  // UNet channels per resolution level
  int64_t feature_dims = 8;                    // affinity features per iteration
  std::vector<int64_t> dilations = {1, 2, 4};  // one filtering iteration per entry
  int64_t kernel_size = 5;
  // Filter radiance / (albedo + kDemodulationEps) and multiply the result by the
  // same factor: texture lives in the albedo, so kernels that reach across it
  // average the (smooth, noisy) shading instead of blurring the texture.
  // Needs "albedo" among input_buffers.
  bool demodulate = false;

  void validate() const;  // throws std::invalid_argument
  int64_t auxChannels() const;
  int64_t albedoOffset() const;  // first aux channel of "albedo"; throws if absent
  // Per iteration: feature_dims features, one bandwidth, one centre weight.
  int64_t guideChannels() const { return int64_t(dilations.size()) * (feature_dims + 2); }
};

// One filtering pass. Output pixel i is sum_j w_ij x_j / sum_j w_ij over the
// kernel_size^2 neighbours j spaced `dilation` apart that lie inside the image,
// with w_ij = exp(-bandwidth_i * |f_i - f_j|^2) and w_ii = centre_i.
// image (B,C,H,W), features (B,D,H,W), bandwidth and centre (B,1,H,W), centre > 0.
// Large images are filtered in bands of rows so no unfolded tensor exceeds
// band_elements floats; the result does not depend on it.
constexpr int64_t kDefaultBandElements = int64_t(32) << 20;  // about 128 MB
torch::Tensor affinityFilter(const torch::Tensor& image, const torch::Tensor& features,
                             const torch::Tensor& bandwidth, const torch::Tensor& centre,
                             int64_t kernel_size, int64_t dilation,
                             int64_t band_elements = kDefaultBandElements);

// Per-iteration kernel parameters decoded from the network's guide maps:
// unit-length features, bandwidth in (0, 20) (1 when the raw output is 0),
// centre weight 4 sigmoid(raw - ln 3) in (0, 4) (1 when the raw output is 0).
struct KernelGuide {
  torch::Tensor features, bandwidth, centre;
};

class KernelNetImpl : public torch::nn::Module {
 public:
  explicit KernelNetImpl(KernelNetConfig config);

  // radiance: linear HDR (B,3,H,W); aux: the raw buffers of config.input_buffers
  // concatenated (B,C,H,W). Returns the filtered linear HDR radiance. Any H, W.
  torch::Tensor forward(const torch::Tensor& radiance, const torch::Tensor& aux);

  // The raw guide maps (B, guideChannels, H, W) and their decoding per iteration.
  torch::Tensor guideMaps(const torch::Tensor& radiance, const torch::Tensor& aux);
  std::vector<KernelGuide> decodeGuides(const torch::Tensor& maps) const;

  const KernelNetConfig& config() const { return config_; }

  // The output layer that produces the guide maps (tests zero it to get a box filter).
  torch::nn::Conv2d head{nullptr};

 private:
  void initializeWeights();
  torch::Tensor unet(const torch::Tensor& inputs);

  KernelNetConfig config_;
  tonemap::Curve curve_;
  torch::nn::ModuleList encoders_, downsamplers_, upsamplers_, decoders_;
};
TORCH_MODULE(KernelNet);

enum class KernelTask { Cleanse, Denoise };
const char* kernelTaskName(KernelTask task);
KernelTask kernelTaskFromName(const std::string& name);  // throws std::invalid_argument

struct KernelModelInfo {
  KernelNetConfig net;
  KernelTask task = KernelTask::Cleanse;
  std::map<std::string, std::string> notes;  // free-form one-line facts (data, steps, ...)
};

std::string kernelModelInfoToText(const KernelModelInfo& info);
// `source` names the file in errors; throws dn::ModelError.
KernelModelInfo kernelModelInfoFromText(const std::string& text, const std::string& source);

// The model file: dn::writeArchiveFile container of kind "kernel-model". Atomic.
void saveKernelModel(const std::string& path, const KernelModelInfo& info, KernelNet& net);
struct LoadedKernelModel {
  KernelModelInfo info;
  KernelNet net{nullptr};
};
LoadedKernelModel loadKernelModel(const std::string& path);  // throws dn::ModelError

// The buffers a frame must have for `config`: "color" plus the input buffers.
std::vector<std::string> requiredBuffers(const KernelNetConfig& config);

// Runs the network on one frame (its "color" and the model's input buffers;
// a missing buffer throws std::out_of_range naming it). Returns linear RGB.
Image runKernelNet(KernelNet& net, const FrameBuffers& frame);

}  // namespace dn
