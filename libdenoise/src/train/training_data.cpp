#include "dn/train/training_data.h"

#include <algorithm>
#include <filesystem>

#include "dn/io/buffer_io.h"
#include "dn/nn/model_inputs.h"

namespace dn {

namespace fs = std::filesystem;

namespace {

torch::Tensor planar(const std::vector<float>& values, const data::Batch& b, int64_t channels) {
  return torch::from_blob(const_cast<float*>(values.data()), {b.size, channels, b.height, b.width},
                          torch::kFloat32)
      .clone();
}

double uniform(torch::Generator& g, double lo, double hi) {
  return lo + (hi - lo) * torch::rand({1}, g).item<double>();
}

torch::Tensor gaussianBlur(const torch::Tensor& x, double sigma) {
  const int64_t radius = std::max<int64_t>(1, static_cast<int64_t>(std::ceil(2.5 * sigma)));
  auto k = torch::arange(-radius, radius + 1, torch::kFloat32);
  k = torch::exp(-k * k / (2 * sigma * sigma));
  k = k / k.sum();
  const int64_t c = x.size(1);
  auto kx = k.view({1, 1, 1, -1}).repeat({c, 1, 1, 1}),
       ky = k.view({1, 1, -1, 1}).repeat({c, 1, 1, 1});
  auto padded = torch::nn::functional::pad(
      x, torch::nn::functional::PadFuncOptions({radius, radius, radius, radius})
             .mode(torch::kReflect));
  auto grouped = torch::nn::functional::Conv2dFuncOptions().groups(c);
  return torch::nn::functional::conv2d(torch::nn::functional::conv2d(padded, kx, grouped), ky,
                                       grouped);
}

bool isImageFile(const fs::path& p) {
  std::string ext = p.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), ::tolower);
  return ext == ".jpg" || ext == ".jpeg" || ext == ".png" || ext == ".exr";
}

}  // namespace

torch::Tensor colorTensor(const data::Batch& batch) { return planar(batch.color, batch, 3); }
torch::Tensor targetTensor(const data::Batch& batch) { return planar(batch.target, batch, 3); }
torch::Tensor auxTensor(const data::Batch& batch) {
  return planar(batch.aux, batch, batch.auxChannels);
}

TrainBatch toTrainBatch(const data::Batch& batch, const std::vector<std::string>& auxBuffers,
                        tonemap::Curve curve) {
  TrainBatch out;
  out.noisy = tonemapRadiance(colorTensor(batch), curve);
  out.target = tonemapRadiance(targetTensor(batch), curve);
  if (!auxBuffers.empty())
    out.aux = normalizeAux(planar(batch.aux, batch, batch.auxChannels), auxBuffers, curve);
  return out;
}

PhotoSource::PhotoSource(const std::vector<std::string>& folders, int64_t maxSide) {
  std::vector<fs::path> files;
  for (const auto& folder : folders) {
    if (!fs::is_directory(folder)) throw IoError(folder + ": no such photo folder");
    for (const auto& e : fs::recursive_directory_iterator(folder))
      if (e.is_regular_file() && isImageFile(e.path())) files.push_back(e.path());
  }
  std::sort(files.begin(), files.end());
  for (const auto& f : files) {
    Image img = readImage(f.string(), 0);
    if (img.width < 256 || img.height < 256) continue;  // icons and thumbnails
    auto t =
        torch::from_blob(img.pixels.data(), {img.height, img.width, img.channels}, torch::kFloat32)
            .permute({2, 0, 1})
            .unsqueeze(0);
    t = img.channels >= 3 ? t.narrow(1, 0, 3).clone() : t.narrow(1, 0, 1).repeat({1, 3, 1, 1});
    if (f.extension() != ".exr") {  // sRGB-encoded -> linear
      t = t.clamp(0, 1);
      t = torch::where(t <= 0.04045, t / 12.92, torch::pow((t + 0.055) / 1.055, 2.4));
    }
    const int64_t side = std::max(t.size(2), t.size(3));
    if (side > maxSide) {  // area-average down to a size where crops hold structure, not blur
      double s = double(maxSide) / side;
      t = torch::nn::functional::interpolate(
          t, torch::nn::functional::InterpolateFuncOptions()
                 .size(std::vector<int64_t>{int64_t(t.size(2) * s), int64_t(t.size(3) * s)})
                 .mode(torch::kArea));
    }
    photos_.push_back(t.squeeze(0).contiguous());
  }
  if (photos_.empty()) throw IoError("(photos): no images found in the photo folders");
}

torch::Tensor PhotoSource::draw(int64_t batch, int64_t crop, torch::Generator& generator) const {
  std::vector<torch::Tensor> crops;
  for (int64_t b = 0; b < batch; ++b) {
    const auto& photo = photos_[torch::randint(0, photos_.size(), {1}, generator).item<int64_t>()];
    const int64_t h = photo.size(1), w = photo.size(2);
    const int64_t y = torch::randint(0, h - crop + 1, {1}, generator).item<int64_t>();
    const int64_t x = torch::randint(0, w - crop + 1, {1}, generator).item<int64_t>();
    auto c = photo.narrow(1, y, crop).narrow(2, x, crop);
    if (uniform(generator, 0, 1) < 0.5) c = c.flip({2});
    if (uniform(generator, 0, 1) < 0.5) c = c.transpose(1, 2);
    crops.push_back(c * std::exp2(uniform(generator, -2.0, 2.5)));  // exposure
  }
  return torch::stack(crops);
}

torch::Tensor degrade(const torch::Tensor& clean, torch::Generator& generator) {
  std::vector<torch::Tensor> out;
  const int64_t h = clean.size(2), w = clean.size(3);
  for (int64_t b = 0; b < clean.size(0); ++b) {
    auto x = clean.narrow(0, b, 1);
    const double pick = uniform(generator, 0, 1);
    if (pick < 0.25) {  // low resolution, as IF stage II sees it
      const int64_t factor = uniform(generator, 0, 1) < 0.5 ? 2 : 4;
      auto small = torch::nn::functional::interpolate(
          x, torch::nn::functional::InterpolateFuncOptions()
                 .size(std::vector<int64_t>{h / factor, w / factor})
                 .mode(torch::kArea));
      x = torch::nn::functional::interpolate(small, torch::nn::functional::InterpolateFuncOptions()
                                                        .size(std::vector<int64_t>{h, w})
                                                        .mode(torch::kBilinear)
                                                        .align_corners(false));
    } else if (pick < 0.4) {
      x = gaussianBlur(x, uniform(generator, 0.5, 2.0));
    }
    // Monte Carlo-like noise: mean-preserving gamma-distributed gain, per pixel and
    // channel (shape k: small k = few samples), plus rare bright fireflies.
    const double k = std::exp(uniform(generator, std::log(0.7), std::log(40.0)));
    auto gain = torch::_standard_gamma(torch::full_like(x, k), generator) / k;
    const double fireflyRate = std::exp(uniform(generator, std::log(1e-4), std::log(3e-3)));
    auto fireflies = (torch::rand(x.sizes(), generator) < fireflyRate).to(torch::kFloat32);
    x = x * gain + fireflies * uniform(generator, 5.0, 60.0) * (x.mean() + 0.05);
    out.push_back(x);
  }
  return torch::cat(out, 0);
}

}  // namespace dn
