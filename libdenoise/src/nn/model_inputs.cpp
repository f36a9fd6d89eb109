#include "dn/nn/model_inputs.h"

#include <ATen/Parallel.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "dn/io/buffers.h"
#include "dn/nn/host_staging.h"

namespace dn {

namespace {

constexpr double kDepthRange = 1000.0;  // scene units; farther (or background) saturates

torch::Tensor applyCurve(const torch::Tensor& v, tonemap::Curve curve) {
  switch (curve) {
    case tonemap::Curve::Log:
      return tonemap::kLogScale * torch::log1p(v);
    case tonemap::Curve::Gamma:
      return tonemap::kGammaScale * torch::pow(v, tonemap::kGammaExponent);
    case tonemap::Curve::Reinhard:
      return v / (1 + v);
    case tonemap::Curve::Linear:
      return v / tonemap::kHdrMax;
    case tonemap::Curve::Srgb:
      break;
  }
  throw std::invalid_argument("unsupported radiance curve for the model");
}

}  // namespace

AuxKind auxKind(const std::string& name) {
  if (name == "normal") return AuxKind::Normal;
  if (name == "depth") return AuxKind::Depth;
  if (name == "color_variance") return AuxKind::Variance;
  if (name == "albedo" || name.find("_color") != std::string::npos || name == "roughness" ||
      name == "metallic" || name == "transmission")
    return AuxKind::Unit;
  return AuxKind::Radiance;  // direct/indirect light, emission, environment
}

torch::Tensor normalizedDepth(const torch::Tensor& depth) {
  return torch::log1p(depth.clamp(0.0, kDepthRange)) / std::log1p(kDepthRange);
}

torch::Tensor tonemapRadiance(const torch::Tensor& radiance, tonemap::Curve curve) {
  return applyCurve(torch::nan_to_num(radiance, 0.0, 0.0, 0.0).clamp(0.0, tonemap::kHdrMax), curve);
}

torch::Tensor inverseTonemapRadiance(const torch::Tensor& t, tonemap::Curve curve) {
  const double top = tonemap::apply(curve, tonemap::kHdrMax);
  torch::Tensor v = t.clamp(0.0, top);
  switch (curve) {
    case tonemap::Curve::Log:
      return torch::expm1(v / tonemap::kLogScale);
    case tonemap::Curve::Gamma:
      return torch::pow(v / tonemap::kGammaScale, 1.0 / tonemap::kGammaExponent);
    case tonemap::Curve::Reinhard:
      return v / (1 - v);
    case tonemap::Curve::Linear:
      return v * tonemap::kHdrMax;
    case tonemap::Curve::Srgb:
      break;
  }
  throw std::invalid_argument("unsupported radiance curve for the model");
}

int64_t auxChannelCount(const std::vector<std::string>& buffers) {
  int64_t channels = 0;
  for (const auto& name : buffers) {
    const BufferSpec* spec = findBufferSpec(name);
    if (!spec || name == "color")
      throw std::invalid_argument("'" + name + "' is not an aux buffer");
    channels += spec->channels;
  }
  return channels;
}

torch::Tensor normalizeAux(const torch::Tensor& aux, const std::vector<std::string>& buffers,
                           tonemap::Curve curve) {
  if (aux.size(1) != auxChannelCount(buffers))
    throw std::invalid_argument("aux tensor has " + std::to_string(aux.size(1)) +
                                " channels, the buffers need " +
                                std::to_string(auxChannelCount(buffers)));
  std::vector<torch::Tensor> parts;
  int64_t offset = 0;
  torch::Tensor clean = torch::nan_to_num(aux, 0.0, 0.0, 0.0);
  for (const auto& name : buffers) {
    const int64_t channels = findBufferSpec(name)->channels;
    torch::Tensor x = clean.narrow(1, offset, channels);
    offset += channels;
    switch (auxKind(name)) {
      case AuxKind::Radiance:
        parts.push_back(tonemapRadiance(x, curve));
        break;
      case AuxKind::Unit:
        parts.push_back(x.clamp(0.0, 1.0));
        break;
      case AuxKind::Normal:
        parts.push_back(x.clamp(-1.0, 1.0));
        break;
      case AuxKind::Depth:
        parts.push_back(normalizedDepth(x));
        break;
      case AuxKind::Variance:
        parts.push_back(0.1 * torch::log1p(x.clamp_min(0.0)));
        break;
    }
  }
  return torch::cat(parts, 1);
}

// Plain loops over rows: a permuted copy_ through LibTorch's TensorIterator
// cost about 15 ns a value, a sizeable share of -q fast.
torch::Tensor imageRegionToTensor(const Image& image, int64_t y0, int64_t x0, int64_t height,
                                  int64_t width) {
  const int64_t channels = image.channels;
  auto region = torch::empty({1, channels, height, width}, torch::kFloat32);
  float* to = region.data_ptr<float>();
  const float* from = image.pixels.data();
  at::parallel_for(0, height, 16, [&](int64_t first, int64_t last) {
    for (int64_t c = 0; c < channels; ++c)
      for (int64_t y = first; y < last; ++y) {
        const float* row = from + ((y0 + y) * image.width + x0) * channels + c;
        float* out = to + (c * height + y) * width;
        for (int64_t x = 0; x < width; ++x) out[x] = row[x * channels];
      }
  });
  return region;
}

torch::Tensor imageToTensor(const Image& image) {
  return imageRegionToTensor(image, 0, 0, image.height, image.width);
}

namespace {

Image deviceTensorToImage(const torch::Tensor& tensor) {
  // Interleaved where the tensor is, so that the host only copies.
  const torch::Tensor hwc = tensor.squeeze(0).to(torch::kFloat32).permute({1, 2, 0}).contiguous();
  const int64_t height = hwc.size(0), width = hwc.size(1), channels = hwc.size(2);
  Image image(static_cast<int>(width), static_cast<int>(height), static_cast<int>(channels));
  floatsToHost(hwc, image.pixels.data());
  return image;
}

}  // namespace

Image tensorToImage(const torch::Tensor& tensor) {
  if (!tensor.is_cpu()) return deviceTensorToImage(tensor);
  const auto chw = tensor.squeeze(0).to(torch::kCPU, torch::kFloat32).contiguous();
  const int64_t channels = chw.size(0), height = chw.size(1), width = chw.size(2);
  Image image(static_cast<int>(width), static_cast<int>(height), static_cast<int>(channels));
  const float* from = chw.data_ptr<float>();
  float* to = image.pixels.data();
  at::parallel_for(0, height, 16, [&](int64_t first, int64_t last) {
    for (int64_t c = 0; c < channels; ++c)
      for (int64_t y = first; y < last; ++y) {
        const float* row = from + (c * height + y) * width;
        float* out = to + y * width * channels + c;
        for (int64_t x = 0; x < width; ++x) out[x * channels] = row[x];
      }
  });
  return image;
}

torch::Tensor imageToDevice(const Image& image, torch::Device device) {
  if (device.is_cpu()) return imageToTensor(image);
  // The stored floats cross as they are, laid out on the device. Converting to
  // half on the host first halved the bytes but cost 39 ms a 1080p buffer on
  // an H200's host (check_cuda.sh), where the copy itself takes about 1 ms.
  return floatsToDevice(image.pixels.data(), {image.height, image.width, image.channels}, device)
      .permute({2, 0, 1})
      .unsqueeze(0);
}

torch::Tensor normalizedAuxRegion(const FrameBuffers& frame,
                                  const std::vector<std::string>& buffers, tonemap::Curve curve,
                                  int64_t y0, int64_t x0, int64_t height, int64_t width,
                                  double exposure) {
  std::vector<torch::Tensor> parts;
  for (const auto& name : buffers) {
    auto part = imageRegionToTensor(frame.get(name), y0, x0, height, width);
    if (exposure != 1.0 && auxKind(name) == AuxKind::Radiance) part.mul_(exposure);
    if (exposure != 1.0 && auxKind(name) == AuxKind::Variance) part.mul_(exposure * exposure);
    parts.push_back(part);
  }
  return normalizeAux(torch::cat(parts, 1), buffers, curve);
}

}  // namespace dn
