#include "dn/infer/control_inputs.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <ATen/Parallel.h>

#include "dn/infer/oidn_filter.h"
#include "dn/nn/model_inputs.h"
#include "dn/tonemap.h"

namespace dn {
namespace {

template <typename F>
torch::Tensor elementwise(const torch::Tensor& x, F f) {
  torch::Tensor out = x.to(torch::kCPU, torch::kFloat32).contiguous().clone();
  float* p = out.data_ptr<float>();
  at::parallel_for(0, out.numel(), 1 << 14, [&](int64_t begin, int64_t end) {
    for (int64_t i = begin; i < end; ++i) p[i] = f(p[i]);
  });
  return out;
}

float finiteOrZero(float v) { return std::isnan(v) ? 0.0f : v; }

torch::Tensor perSample(const torch::Tensor& values, const torch::Tensor& like) {
  return values.to(torch::kFloat32).view({like.size(0), 1, 1, 1});
}

// A network on a batch zero-padded to the alignment, cut back to its size.
torch::Tensor runAligned(OidnUNet net, const torch::Tensor& x) {
  const int64_t h = x.size(2), w = x.size(3);
  const int64_t padH = (kOidnAlignment - h % kOidnAlignment) % kOidnAlignment;
  const int64_t padW = (kOidnAlignment - w % kOidnAlignment) % kOidnAlignment;
  return net->forward(torch::constant_pad_nd(x, {0, padW, 0, padH}, 0.0))
      .narrow(2, 0, h)
      .narrow(3, 0, w);
}

}  // namespace

torch::Tensor cleanAux(const OidnBase& base, const torch::Tensor& albedo,
                       const torch::Tensor& normal) {
  const torch::Tensor unexposed = torch::ones({albedo.size(0)});
  auto clean = [&](const char* setName, const torch::Tensor& buffer) {
    const OidnInputSet set = oidnInputSet(setName);  // a copy: setName becomes a temporary string
    return oidnOutputDecode(runAligned(base->net(setName), oidnBaseInput(buffer, set, unexposed)),
                            set, 1.0f);
  };
  return torch::cat({clean("alb", albedo), clean("nrm", normal)}, 1);
}

torch::Tensor puEncode(const torch::Tensor& radiance) {
  if (!radiance.is_cpu())  // the same curve in tensor operations where the tensor is
    return puEncodeTensor(
        torch::nan_to_num(radiance.to(torch::kFloat32), 0.0, std::numeric_limits<float>::max(), 0.0)
            .clamp(0.0f, std::numeric_limits<float>::max()));
  return elementwise(radiance, [](float v) {
    return tonemap::pu(std::clamp(finiteOrZero(v), 0.0f, std::numeric_limits<float>::max()));
  });
}

torch::Tensor puDecode(const torch::Tensor& encoded) {
  return elementwise(encoded, [](float v) {
    return std::min(tonemap::puInverse(std::max(finiteOrZero(v), 0.0f)),
                    std::numeric_limits<float>::max());
  });
}

torch::Tensor oidnBaseInput(const torch::Tensor& buffers, const OidnInputSet& set,
                            const torch::Tensor& exposure) {
  std::vector<torch::Tensor> parts;
  for (size_t b = 0; b < set.buffers.size(); ++b) {
    const torch::Tensor x = torch::nan_to_num(buffers.narrow(1, 3 * b, 3), 0.0, 0.0, 0.0);
    if (set.buffers[b] == "color")
      // Multiplied in float as oidnInput does, before the PU curve.
      parts.push_back(puEncode(x * perSample(exposure, x)));
    else if (set.buffers[b] == "albedo" && b == 0)  // the albedo network's own input
      parts.push_back(elementwise(x.clamp(0.0, 1.0), tonemap::srgbEncode));
    else if (set.buffers[b] == "albedo")
      parts.push_back(x.clamp(0.0, 1.0));
    else
      parts.push_back(x.clamp(-1.0, 1.0) * 0.5 + 0.5);
  }
  return torch::cat(parts, 1);
}

torch::Tensor controlHintExtras(const OidnControlConfig& config, const torch::Tensor& extras,
                                const torch::Tensor& present, const torch::Tensor& exposure) {
  std::vector<torch::Tensor> parts;
  int64_t offset = 0;
  for (const auto& name : config.extra_buffers) {
    const int64_t channels = findBufferSpec(name)->channels;
    const torch::Tensor x = torch::nan_to_num(extras.narrow(1, offset, channels), 0.0, 0.0, 0.0);
    offset += channels;
    switch (auxKind(name)) {
      case AuxKind::Radiance:
        parts.push_back(puEncode(x * perSample(exposure, x)));
        break;
      case AuxKind::Unit:
        parts.push_back(x.clamp(0.0, 1.0));
        break;
      case AuxKind::Normal:
        parts.push_back(x.clamp(-1.0, 1.0) * 0.5 + 0.5);
        break;
      case AuxKind::Depth:
        parts.push_back(normalizedDepth(x));
        break;
      case AuxKind::Variance:
        parts.push_back(puEncode(x * perSample(exposure * exposure, x)));
        break;
    }
  }
  const int64_t b = extras.size(0), h = extras.size(2), w = extras.size(3);
  if (!config.extra_buffers.empty())
    parts.push_back(present.to(torch::kFloat32).view({b, -1, 1, 1}).expand({b, -1, h, w}));
  return parts.empty() ? extras.new_zeros({b, 0, h, w}) : torch::cat(parts, 1);
}

torch::Tensor withDiffusionState(const torch::Tensor& hintExtras, const torch::Tensor& state,
                                 const torch::Tensor& sigma) {
  const int64_t b = state.size(0), h = state.size(2), w = state.size(3);
  return torch::cat(
      {hintExtras, state, (perSample(sigma, state) * kSigmaInputScale).expand({b, 1, h, w})}, 1);
}

torch::Tensor controlHint(const OidnControlConfig& config, const torch::Tensor& extras,
                          const torch::Tensor& present, const torch::Tensor& exposure,
                          const torch::Tensor& state, const torch::Tensor& sigma) {
  const torch::Tensor hint = controlHintExtras(config, extras, present, exposure);
  return config.diffusion ? withDiffusionState(hint, state, sigma) : hint;
}

namespace {

// The extra buffers in the config's order, stacked (`present(image)` gives a
// buffer the frame has, zeros of its channel count stand in for one it
// lacks), and which are present, on `options`' device.
template <class Present>
std::pair<torch::Tensor, torch::Tensor> stackExtras(const FrameBuffers& frame,
                                                    const OidnControlConfig& config, int64_t height,
                                                    int64_t width,
                                                    const torch::TensorOptions& options,
                                                    const Present& present) {
  std::vector<torch::Tensor> parts;
  std::vector<float> flags;
  for (const auto& name : config.extra_buffers) {
    const int64_t channels = findBufferSpec(name)->channels;
    const bool has = frame.has(name);
    flags.push_back(has ? 1.0f : 0.0f);
    parts.push_back(has ? present(frame.get(name))
                        : torch::zeros({1, channels, height, width}, options));
  }
  torch::Tensor extras =
      parts.empty() ? torch::zeros({1, 0, height, width}, options) : torch::cat(parts, 1);
  return {extras, torch::tensor(flags).view({1, -1}).to(options.device())};
}

}  // namespace

std::pair<torch::Tensor, torch::Tensor> frameExtras(const FrameBuffers& frame,
                                                    const OidnControlConfig& config,
                                                    const TileRect& r) {
  return stackExtras(frame, config, r.height, r.width, torch::TensorOptions(),
                     [&](const Image& image) {
                       return imageRegionToTensor(image, r.y0, r.x0, r.height, r.width);
                     });
}

std::pair<torch::Tensor, torch::Tensor> frameExtrasOnDevice(const FrameBuffers& frame,
                                                            const OidnControlConfig& config,
                                                            torch::Device device) {
  return stackExtras(frame, config, frame.height, frame.width,
                     torch::TensorOptions().dtype(torch::kFloat).device(device),
                     [&](const Image& image) { return imageToDevice(image, device); });
}

}  // namespace dn
