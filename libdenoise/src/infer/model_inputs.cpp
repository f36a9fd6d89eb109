#include "dn/infer/model_inputs.h"

#include <cmath>
#include <stdexcept>

#include "dn/io/buffers.h"

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

torch::Tensor imageRegionToTensor(const Image& image, int64_t y0, int64_t x0, int64_t height,
                                  int64_t width) {
  auto hwc = torch::from_blob(const_cast<float*>(image.pixels.data()),
                              {image.height, image.width, image.channels}, torch::kFloat32);
  auto region = torch::empty({1, image.channels, height, width}, torch::kFloat32);
  // copy_ always copies; contiguous() would alias the image for one channel.
  region[0].copy_(hwc.narrow(0, y0, height).narrow(1, x0, width).permute({2, 0, 1}));
  return region;
}

torch::Tensor imageToTensor(const Image& image) {
  return imageRegionToTensor(image, 0, 0, image.height, image.width);
}

Image tensorToImage(const torch::Tensor& tensor) {
  const auto chw = tensor.squeeze(0);
  Image image(static_cast<int>(chw.size(2)), static_cast<int>(chw.size(1)),
              static_cast<int>(chw.size(0)));
  // Straight into the image's pixels: no intermediate full-frame copy.
  torch::from_blob(image.pixels.data(), {image.height, image.width, image.channels},
                   torch::kFloat32)
      .copy_(chw.permute({1, 2, 0}));
  return image;
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
