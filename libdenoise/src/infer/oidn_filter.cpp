#include "dn/infer/oidn_filter.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <ATen/Parallel.h>
#include <ATen/record_function.h>

#include "dn/nn/model_inputs.h"
#include "dn/pu_curve.h"
#include "dn/tonemap.h"

namespace dn {
namespace {

float nanToZero(float v) { return std::isnan(v) ? 0.0f : v; }

float encodeNormal(float v) { return std::clamp(v, -1.0f, 1.0f) * 0.5f + 0.5f; }

// libtonemap's curves as tensor operations, for inputs and outputs made on a
// GPU: the same formulas in float, on values already clamped at 0.
float puNorm() {  // the unscaled curve at 65504, as libtonemap computes it
  using namespace tonemap::pu_curve;
  return kE * std::log(kHalfMax + kF) + kG;
}
torch::Tensor puDecodeOnDevice(const torch::Tensor& t) {
  using namespace tonemap::pu_curve;
  const torch::Tensor x = t * puNorm();
  return torch::where(
      x <= kX0, x / kA,
      torch::where(x <= kX1, ((x - kD) / kB).pow(1.0f / kC), ((x - kG) / kE).exp() - kF));
}
torch::Tensor srgbEncodeOnDevice(const torch::Tensor& v) {
  return torch::where(v <= 0.0031308f, v * 12.92f, v.pow(1.0f / 2.4f) * 1.055f - 0.055f);
}
torch::Tensor srgbDecodeOnDevice(const torch::Tensor& e) {
  return torch::where(e <= 0.04045f, e / 12.92f, ((e + 0.055f) / 1.055f).pow(2.4f));
}

torch::Tensor nanToZero(const torch::Tensor& t) {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  return t.nan_to_num(0.0, kInf, -kInf);
}

// Fills three planes of `out` (h x w each) from a 3-channel image, or from a
// 1-channel one broadcast, as OIDN does; rows in parallel.
template <typename Transform>
void fillPlanes(const Image& image, const TileRect& r, float* out, Transform transform) {
  const int64_t plane = r.height * r.width;
  at::parallel_for(0, r.height, 16, [&](int64_t begin, int64_t end) {
    for (int64_t y = begin; y < end; ++y)
      for (int64_t x = 0; x < r.width; ++x) {
        const float* p = image.pixel(int(r.x0 + x), int(r.y0 + y));
        for (int c = 0; c < 3; ++c) {
          const float v = nanToZero(p[image.channels >= 3 ? c : 0]);
          out[c * plane + y * r.width + x] = transform(v);
        }
      }
  });
}

}  // namespace

torch::Tensor puEncodeTensor(const torch::Tensor& y) {
  using namespace tonemap::pu_curve;
  return torch::where(y <= kY0, y * kA,
                      torch::where(y <= kY1, y.pow(kC) * kB + kD, (y + kF).log() * kE + kG)) /
         puNorm();
}

// The tiles a frame is run in. The whole frame when its pixels fit the budget
// (a square tile from the budget alone would split a 1920x1080 frame, 2.1
// MPix, into two 1840-pixel-wide tiles that overlap almost entirely). Else
// square tiles of the budget's side, or full-height columns of the same area
// where the frame is at most 2160 tall, whichever runs the networks over fewer
// pixels: at 3840x2160 and a 1584-px side, 5 columns of 1152 x 2160 (12.4
// MPix) against 6 squares (15.1 MPix).
Tiler planOidnTiles(int64_t height, int64_t width, double bytesPerPixel, int64_t blend,
                    const OidnRunOptions& options) {
  if (options.tile > 0) return Tiler(height, width, options.tile, blend);
  const bool underCap = options.maxTilePixels <= 0 || height * width <= options.maxTilePixels;
  if (underCap && height * width * bytesPerPixel <= options.maxMemoryBytes)
    return Tiler(height, width, 0, blend);
  int64_t side = tileSizeForMemory(options.maxMemoryBytes, bytesPerPixel, kOidnAlignment);
  if (options.maxTilePixels > 0) side = std::min<int64_t>(2160, side);
  Tiler squares(height, width, side, blend);
  const int64_t columnWidth = side * side / height / kOidnAlignment * kOidnAlignment;
  if (height > 2160 || columnWidth < 2 * blend) return squares;
  Tiler columns(height, width, height, columnWidth, blend);
  return tiledPixels(columns) < tiledPixels(squares) ? columns : squares;
}

double deviceMemoryBudget(double freeBytes) {
  return kDeviceBudgetShare * std::max(0.0, freeBytes);
}

torch::Tensor oidnInput(const FrameBuffers& frame, const OidnInputSet& set, float exposure,
                        const TileRect& r) {
  auto input = torch::empty({1, set.channels(), r.height, r.width});
  float* data = input.data_ptr<float>();
  const int64_t plane = r.height * r.width;
  for (size_t b = 0; b < set.buffers.size(); ++b) {
    const std::string& name = set.buffers[b];
    float* out = data + 3 * b * plane;
    if (name == "color")
      fillPlanes(frame.get(name), r, out, [exposure](float v) {
        return tonemap::pu(std::clamp(v * exposure, 0.0f, std::numeric_limits<float>::max()));
      });
    else if (name == "albedo" && b == 0)  // the albedo network's own input, in sRGB
      fillPlanes(frame.get(name), r, out,
                 [](float v) { return tonemap::srgbEncode(std::clamp(v, 0.0f, 1.0f)); });
    else if (name == "albedo")
      fillPlanes(frame.get(name), r, out, [](float v) { return std::clamp(v, 0.0f, 1.0f); });
    else
      fillPlanes(frame.get(name), r, out, encodeNormal);
  }
  return input;
}

namespace {

// The region of a buffer on `device`, (3, h, w): from `onDevice` where it is
// there, else the region's pixels as stored (3 channels, or 1 broadcast),
// moved as they are.
torch::Tensor regionOnDevice(const FrameBuffers& frame, const std::string& name, const TileRect& r,
                             torch::Device device, const DeviceBuffers& onDevice) {
  if (auto it = onDevice.find(name); it != onDevice.end())
    return it->second.narrow(1, r.y0, r.height).narrow(2, r.x0, r.width);
  const Image& image = frame.get(name);
  return torch::from_blob(const_cast<float*>(image.pixels.data()),
                          {image.height, image.width, image.channels})
      .narrow(0, r.y0, r.height)
      .narrow(1, r.x0, r.width)
      .narrow(2, 0, image.channels >= 3 ? 3 : 1)
      .to(device)
      .permute({2, 0, 1})
      .expand({3, r.height, r.width});
}

torch::Tensor scalarOn(float value, torch::Device device) {
  return torch::full({}, value, torch::TensorOptions().dtype(torch::kFloat).device(device));
}

}  // namespace

torch::Tensor bufferOnDevice(const Image& image, torch::Device device) {
  return bufferOnDevice(imageToDevice(image, device));
}

torch::Tensor bufferOnDevice(const torch::Tensor& stored) {
  // The stored channels cross, one is broadcast there.
  const torch::Tensor planes = stored.squeeze(0);
  const torch::Tensor three = planes.narrow(0, 0, planes.size(0) >= 3 ? 3 : 1);
  return three.expand({3, planes.size(1), planes.size(2)});
}

torch::Tensor oidnInputOnDevice(const FrameBuffers& frame, const OidnInputSet& set, float exposure,
                                const TileRect& r, torch::Device device,
                                const DeviceBuffers& onDevice) {
  return oidnInputOnDevice(frame, set, scalarOn(exposure, device), r, device, onDevice);
}

torch::Tensor oidnInputOnDevice(const FrameBuffers& frame, const OidnInputSet& set,
                                const torch::Tensor& exposure, const TileRect& r,
                                torch::Device device, const DeviceBuffers& onDevice) {
  std::vector<torch::Tensor> planes;
  for (size_t b = 0; b < set.buffers.size(); ++b) {
    const std::string& name = set.buffers[b];
    torch::Tensor v = nanToZero(regionOnDevice(frame, name, r, device, onDevice));
    if (name == "color")
      v = puEncodeTensor((v * exposure).clamp(0.0f, std::numeric_limits<float>::max()));
    else if (name == "albedo" && b == 0)
      v = srgbEncodeOnDevice(v.clamp(0.0f, 1.0f));
    else if (name == "albedo")
      v = v.clamp(0.0f, 1.0f);
    else
      v = v.clamp(-1.0f, 1.0f) * 0.5f + 0.5f;
    planes.push_back(v);
  }
  return torch::cat(planes).unsqueeze(0);
}

torch::Tensor oidnOutputDecode(const torch::Tensor& output, const OidnInputSet& set,
                               float exposure) {
  if (!output.is_cpu()) return oidnOutputDecodeOnDevice(output, set, exposure);
  auto out = output.to(torch::kCPU, torch::kFloat32).contiguous();
  float* p = out.data_ptr<float>();
  const float scale = exposure != 0.0f ? 1.0f / exposure : 0.0f;
  constexpr float kMax = std::numeric_limits<float>::max();
  // NaN and negatives as 0, as OIDN; what overflows float is clamped, not Inf.
  auto decode = [&](auto transform) {
    at::parallel_for(0, out.numel(), 1 << 14, [&](int64_t begin, int64_t end) {
      for (int64_t i = begin; i < end; ++i) p[i] = transform(std::max(nanToZero(p[i]), 0.0f));
    });
  };
  if (set.denoised() == "color")
    decode([&](float v) { return std::min(tonemap::puInverse(v) * scale, kMax); });
  else if (set.denoised() == "albedo")
    decode([](float v) { return std::min(tonemap::srgbDecode(v), 1.0f); });
  else
    decode([](float v) { return std::clamp(v * 2.0f - 1.0f, -1.0f, 1.0f); });
  return out;
}

torch::Tensor oidnOutputDecodeOnDevice(const torch::Tensor& output, const OidnInputSet& set,
                                       float exposure) {
  return oidnOutputDecodeOnDevice(output, set, scalarOn(exposure, output.device()));
}

torch::Tensor oidnOutputDecodeOnDevice(const torch::Tensor& output, const OidnInputSet& set,
                                       const torch::Tensor& exposure) {
  const torch::Tensor v = nanToZero(output.to(torch::kFloat32)).clamp_min(0.0f);
  if (set.denoised() == "color") {
    const torch::Tensor scale =
        torch::where(exposure != 0.0f, exposure.reciprocal(), torch::zeros_like(exposure));
    return (puDecodeOnDevice(v) * scale).clamp_max(std::numeric_limits<float>::max());
  }
  if (set.denoised() == "albedo") return srgbDecodeOnDevice(v).clamp_max(1.0f);
  return (v * 2.0f - 1.0f).clamp(-1.0f, 1.0f);
}

torch::Tensor oidnExposureOnDevice(const torch::Tensor& color) {
  constexpr int64_t kBin = 16;
  const int64_t height = color.size(-2), width = color.size(-1);
  const torch::Tensor c = color.reshape({-1, height, width})
                              .to(torch::kFloat)
                              .nan_to_num(0.0, std::numeric_limits<float>::max(), 0.0)
                              .clamp_min(0.0f);
  const bool rgb = c.size(0) >= 3;
  // Luminance in float, term by term as libtonemap sums it.
  const torch::Tensor luminance =
      c[0] * 0.212671f + c[rgb ? 1 : 0] * 0.715160f + c[rgb ? 2 : 0] * 0.072169f;
  // Bin b of n along an axis of `size` spans [b size / n, (b + 1) size / n): a
  // 0/1 matrix of bins by pixels, so that the bins' sums are two products in
  // double (deterministic, unlike scattered atomic adds).
  const auto longs = torch::TensorOptions().dtype(torch::kLong).device(color.device());
  auto membership = [&](int64_t size) {
    const int64_t bins = (size + kBin - 1) / kBin;
    // Integer division, as libtonemap's: a tensor's `/` would divide exactly.
    const torch::Tensor edges = torch::div(torch::arange(bins + 1, longs) * size, bins, "floor");
    const torch::Tensor pixel = torch::arange(size, longs).unsqueeze(0);
    return ((pixel >= edges.narrow(0, 0, bins).unsqueeze(1)) &
            (pixel < edges.narrow(0, 1, bins).unsqueeze(1)))
        .to(torch::kDouble);
  };
  const torch::Tensor rows = membership(height), columns = membership(width);
  const torch::Tensor sums = rows.matmul(luminance.to(torch::kDouble)).matmul(columns.t());
  const torch::Tensor counts = rows.sum(1).unsqueeze(1) * columns.sum(1).unsqueeze(0);
  // Each bin's mean rounded to float, as libtonemap computes it.
  const torch::Tensor mean = (sums.to(torch::kFloat) / counts.to(torch::kFloat)).to(torch::kDouble);
  const torch::Tensor lit = mean > 1e-8f;
  const torch::Tensor count = lit.sum().to(torch::kDouble);
  const torch::Tensor logSum = torch::where(lit, mean.log2(), torch::zeros_like(mean)).sum();
  const torch::Tensor exposure = 0.18 / torch::exp2(logSum / count.clamp_min(1.0));
  return torch::where(count > 0, exposure, torch::ones_like(exposure)).to(torch::kFloat);
}

double oidnBytesPerPixel(const OidnUNetConfig& config) {
  // The full-resolution decoder level dominates: the concatenation of the
  // upsampled features with the input, the convolution's output and the input
  // itself are alive at once; the coarser levels and oneDNN's buffers add about half.
  const auto convs = oidnConvs(config);
  const OidnConv& last = *std::find_if(convs.begin(), convs.end(), [&](const OidnConv& c) {
    return c.in > config.in_channels && c.name.rfind("dec_conv1a", 0) == 0;
  });
  return 4.0 * double(last.in + last.out + config.in_channels) * 1.5;
}

OidnRunResult runOidn(OidnUNet& net, const OidnInputSet& set, const FrameBuffers& frame,
                      const OidnRunOptions& options) {
  OidnRunResult result;
  const bool onHost = options.device.is_cpu();
  const bool colour = set.denoised() == "color";
  // On a GPU each buffer crosses once, whole (tiles are views of it), and
  // everything after runs there, the autoexposure too, up to the caller's
  // one copy of the result back.
  DeviceBuffers onDevice = options.onDevice;
  torch::Tensor exposure;  // on the device
  if (!onHost) {
    RECORD_FUNCTION("dn::upload", std::vector<c10::IValue>());
    const bool sent = options.uploads && options.uploads->holds(frame);
    for (const std::string& name : set.buffers)
      if (!onDevice.count(name))
        onDevice[name] = sent ? bufferOnDevice(options.uploads->stored(name))
                              : bufferOnDevice(frame.get(name), options.device);
  }
  // Albedo and normal are denoised at their own scale, as OIDN does.
  if (!colour)
    result.exposure = 1.0f;
  else if (options.exposure > 0.0f)
    result.exposure = options.exposure;
  else if (onHost)
    result.exposure = tonemap::oidnExposure(frame.get("color"));
  else
    exposure = oidnExposureOnDevice(onDevice.at("color"));
  if (!onHost && !exposure.defined()) exposure = scalarOn(result.exposure, options.device);

  const OidnUNetConfig& config = net->config();
  const int64_t overlap = config.arch == OidnArch::Large ? kOidnOverlapLarge : kOidnOverlap;
  // The Tiler gives every pixel within overlap / 4 of an inner tile edge zero
  // weight: at four times OIDN's overlap, each pixel that counts has as much
  // context as OIDN gives it.
  const Tiler tiler =
      planOidnTiles(frame.height, frame.width, oidnBytesPerPixel(config), 4 * overlap, options);
  result.tileSize = std::max(tiler.tiles().front().height, tiler.tiles().front().width);
  result.tileCount = tiler.tiles().size();

  std::size_t done = 0;
  result.image = tiler.apply([&](const TileRect& r) {
    torch::Tensor x;
    {
      RECORD_FUNCTION("dn::oidnInput", std::vector<c10::IValue>());
      x = onHost ? oidnInput(frame, set, result.exposure, r)
                 : oidnInputOnDevice(frame, set, exposure, r, options.device, onDevice);
      const int64_t padH = (kOidnAlignment - r.height % kOidnAlignment) % kOidnAlignment;
      const int64_t padW = (kOidnAlignment - r.width % kOidnAlignment) % kOidnAlignment;
      x = torch::constant_pad_nd(x, {0, padW, 0, padH}, 0.0)
              .to(options.device)
              .contiguous(torch::MemoryFormat::ChannelsLast);
    }
    torch::Tensor y;
    {
      RECORD_FUNCTION("dn::network", std::vector<c10::IValue>());
      y = (options.network ? options.network(x, r) : net->forward(x))
              .narrow(2, 0, r.height)
              .narrow(3, 0, r.width);
    }
    RECORD_FUNCTION("dn::oidnOutputDecode", std::vector<c10::IValue>());
    torch::Tensor decoded = onHost ? oidnOutputDecode(y, set, result.exposure)
                                   : oidnOutputDecodeOnDevice(y, set, exposure);
    if (options.progress) options.progress(double(++done) / tiler.tiles().size());
    return decoded;
  });
  // The one value the host needs back, read once the frame's work is queued.
  if (!onHost && colour && options.exposure <= 0.0f)
    result.exposure = options.deferExposureRead ? 0.0f : exposure.item<float>();
  result.exposureOnDevice = exposure;
  return result;
}

}  // namespace dn
