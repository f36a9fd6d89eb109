// OIDN's RT denoising UNet in LibTorch, with OIDN's tensor names
// ("enc_conv0.weight", ...), so the weights of libOpenImageDenoise load as
// they are (dntrain import-oidn). Three sizes, as OIDN ships them: the default
// (5 levels, 32..112 channels), small (32..64 channels) and large (64..256).
// Every convolution is 3x3 with ReLU, pooling is 2x2 max, upsampling 2x nearest;
// the decoder concatenates the pooled encoder features and, last, the input.
// Inputs must be multiples of kOidnAlignment in height and width.
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include <torch/torch.h>

#include "dn/nn/prior.h"

namespace dn {

constexpr int64_t kOidnAlignment = 16;

enum class OidnArch { Default, Small, Large };
const char* oidnArchName(OidnArch arch);
OidnArch oidnArchFromName(const std::string& name);  // throws std::invalid_argument

struct OidnUNetConfig {
  OidnArch arch = OidnArch::Default;
  int64_t in_channels = 9;  // 3 colour, + 3 albedo, + 3 normal
  int64_t out_channels = 3;
  bool encoder_only = false;  // the enc_* convolutions alone (a Control Module's copy)
  // false: weights left uninitialised, for a loader that replaces every one of
  // them (random initialisation of a whole base costs 0.08 s a process).
  bool initialise = true;
};

// A 3x3 convolution's weight and bias (named as torch::nn::Conv2d names them),
// initialised as torch::nn::Conv2d does, or left uninitialised.
class OidnConv3x3Impl : public torch::nn::Module {
 public:
  OidnConv3x3Impl(int64_t in, int64_t out, bool initialise);
  torch::Tensor weight, bias;
};
TORCH_MODULE(OidnConv3x3);

// One convolution of the network: its OIDN name and channel counts.
struct OidnConv {
  std::string name;
  int64_t in, out;
};
// Every convolution of `config`, in the order the network runs them.
std::vector<OidnConv> oidnConvs(const OidnUNetConfig& config);

class OidnUNetImpl : public torch::nn::Module {
 public:
  explicit OidnUNetImpl(const OidnUNetConfig& config);

  // (B, in_channels, H, W) in OIDN's input space -> (B, out_channels, H, W).
  // `residuals`, when given, are added to the decoder's skip inputs (the pooled
  // encoder features, coarse to fine, then the input itself) and to the
  // bottleneck output: where a Control Module steers the network.
  torch::Tensor forward(const torch::Tensor& input, const ControlResiduals* residuals = nullptr);

  // The two halves of forward, so that a Control Module can run the frozen
  // encoder once and the decoder once per diffusion step.
  struct Features {
    std::vector<torch::Tensor> skips;  // decoder order: coarse to fine, the input last
    torch::Tensor bottleneck;
  };
  Features encode(const torch::Tensor& input);
  torch::Tensor decode(const Features& features, const ControlResiduals* residuals = nullptr);

  // Channels of the decoder's skip inputs (coarse to fine, the input last) and
  // of the bottleneck output: the shapes ControlResiduals must have.
  std::vector<int64_t> skipChannels() const;
  int64_t bottleneckChannels() const;

  const OidnUNetConfig& config() const { return config_; }

  // Inner convolutions in a reduced precision, kBFloat16 or kHalf (float
  // accumulation; copies of the float weights made on first use): bfloat16 is
  // about twice as fast where the CPU multiplies bfloat16 matrices
  // (cpuHasBFloat16Matrix); half is what OIDN's CUDA device runs, on a GPU
  // only. The first and the output convolution and the input's share of the
  // last decoder level stay in float; outputs are float. kFloat: float
  // throughout, bit for bit as before.
  void useInnerPrecision(torch::ScalarType type);
  torch::ScalarType innerPrecision() const { return inner_; }
  void useBFloat16(bool on) { useInnerPrecision(on ? torch::kBFloat16 : torch::kFloat); }
  bool usesBFloat16() const { return inner_ == torch::kBFloat16; }
  // Weights in channels-last order: faster convolutions on the CPU. Once.
  void useChannelsLast();

 private:
  struct Weights {
    torch::Tensor weight, bias;
  };
  // A copy made from a float weight, remade when that weight changes (its
  // storage, version, device or layout) or the precision does.
  struct Derived {
    Weights weights;
    const void* source = nullptr;
    int64_t version = 0;
  };
  bool inReducedPrecision(const std::string& name) const;
  Weights weights(const std::string& name);  // in the convolution's precision
  // The upsampled share of an upConv's weight folded into four 2x2 phases, in
  // its precision and layout: made once, not on every call.
  torch::Tensor foldedWeight(const std::string& name, int64_t coarseChannels,
                             torch::MemoryFormat format);
  torch::Tensor conv(const std::string& name, const torch::Tensor& x);
  // conv(name, cat(upsample2x(coarse), skip)) without the upsampled copy.
  torch::Tensor upConv(const std::string& name, const torch::Tensor& coarse,
                       const torch::Tensor& skip);

  OidnUNetConfig config_;
  std::vector<std::vector<std::string>> encoder_;  // per level, pooled after the last
  std::vector<std::string> bottleneck_;            // at the coarsest level
  std::vector<std::vector<std::string>> decoder_;  // per level, after upsampling and concat
  std::map<std::string, OidnConv3x3> convs_;
  torch::ScalarType inner_ = torch::kFloat;
  bool channelsLast_ = false;
  std::map<std::string, Derived> reduced_;
  std::map<std::string, Derived> folded_;
};
TORCH_MODULE(OidnUNet);

// OIDN's input sets, named as OIDN names its weights: colour alone ("hdr"),
// + albedo ("hdr_alb"), + albedo + normal ("hdr_alb_nrm"); and the networks of
// OIDN's prefilter mode at its default quality: albedo alone ("alb"), normal
// alone ("nrm"), and the large network for colour + prefiltered albedo +
// normal ("hdr_calb_cnrm_large").
struct OidnInputSet {
  std::string name;
  std::vector<std::string> buffers;  // canonical buffer names, the denoised one first
  bool cleanAux = false;             // trained on noise-free albedo and normal
  bool large = false;                // always OidnArch::Large, whatever the base's size
  int64_t channels() const { return 3 * static_cast<int64_t>(buffers.size()); }
  const std::string& denoised() const { return buffers.front(); }
};
const std::vector<OidnInputSet>& oidnInputSets();
const OidnInputSet& oidnInputSet(const std::string& name);  // throws std::invalid_argument

// The pretrained base: one network per input set, all of one size (but for the
// large prefilter network), as OIDN picks its weights by the buffers it is given.
class OidnBaseImpl : public torch::nn::Module {
 public:
  OidnBaseImpl(OidnArch arch, const std::vector<std::string>& inputSets, bool initialise = true);

  // The colour network for the richest set whose buffers are all in `available`
  // (noisy aux), and its set; nullptr when none fits (no colour).
  std::pair<OidnUNet, const OidnInputSet*> pick(const std::vector<std::string>& available) const;
  const OidnInputSet* pickSet(const std::vector<std::string>& available) const;  // pick's set
  // Whether the base holds the three networks of the prefilter mode.
  bool canPrefilter() const;
  OidnUNet net(const std::string& inputSet) const;  // throws std::out_of_range
  const std::vector<std::string>& inputSets() const { return sets_; }
  // Weights in channels-last order: faster convolutions on the CPU. Each
  // network is converted when net() or pick() first hands it out, so that a
  // run converts only the networks it uses.
  void useChannelsLast() { channelsLast_ = true; }
  // Every network's inner convolutions in `type` (OidnUNetImpl::useInnerPrecision).
  void useInnerPrecision(torch::ScalarType type);
  void useBFloat16(bool on) { useInnerPrecision(on ? torch::kBFloat16 : torch::kFloat); }

 private:
  std::vector<std::string> sets_;
  std::map<std::string, OidnUNet> nets_;
  bool channelsLast_ = false;
};
TORCH_MODULE(OidnBase);

// Whether the CPU multiplies bfloat16 matrices in hardware (Intel AMX), where
// oneDNN's bfloat16 convolutions run about twice as fast as float ones.
bool cpuHasBFloat16Matrix();

}  // namespace dn
