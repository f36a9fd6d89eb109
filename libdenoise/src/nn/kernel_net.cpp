#include "dn/nn/kernel_net.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include "dn/nn/model_file.h"
#include "dn/nn/model_inputs.h"
#include "dn/nn/nn_blocks.h"

namespace dn {
namespace {

namespace F = torch::nn::functional;

// Keeps the kernel normaliser away from zero when every neighbour weight underflows.
constexpr double kMinCentreWeight = 1e-4;
// Features are unit vectors (|f_i - f_j|^2 <= 4) and bandwidths stay below this,
// so a neighbour's weight never underflows to 0: unbounded, both grew without
// limit in training until every kernel was exactly the identity and the
// affinity gradients were exactly 0 (a dead network). exp(-4 * 20) ~ 2e-35.
constexpr double kMaxBandwidth = 20.0;
constexpr double kFeatureNormEps = 1e-6;
// The centre weight is bounded too: unbounded, raising it everywhere was the
// cheapest way out of the initial blur and training ended at the identity, where
// the affinities get no gradient. With this bound a pixel keeps itself only by
// making its neighbours' features differ (texture and geometry edges).
constexpr double kMaxCentreWeight = 4.0;
// Written into model files so a change of parametrisation is detected on load.
constexpr const char* kCentreWeightParametrisation = "sigmoid4";

constexpr double kLeakySlope = 0.1;

torch::nn::Sequential convPair(int64_t in, int64_t out) {
  const auto options = torch::nn::LeakyReLUOptions().negative_slope(kLeakySlope);
  return torch::nn::Sequential(nn::conv3x3(in, out), torch::nn::LeakyReLU(options),
                               nn::conv3x3(out, out), torch::nn::LeakyReLU(options));
}

// The k x k neighbourhoods, spaced `dilation` apart, of rows [y0, y0 + rows) of
// a zero-padded (B,C,H+2r,W+2r) tensor, as (B,C,k,k,rows,W). Without autograd a
// strided view (no copy, twice as fast as im2col); with it unfold, whose
// backward is faster than that of an overlapping strided view.
torch::Tensor neighbourhoods(const torch::Tensor& padded, int64_t kernel_size, int64_t dilation,
                             int64_t y0, int64_t rows, int64_t width) {
  const auto band = padded.narrow(2, y0, rows + 2 * dilation * (kernel_size / 2));
  const std::vector<int64_t> shape = {band.size(0), band.size(1), kernel_size,
                                      kernel_size,  rows,         width};
  if (torch::GradMode::is_enabled())
    return F::unfold(band, F::UnfoldFuncOptions(kernel_size).dilation(dilation)).view(shape);
  const auto s = band.strides();
  return band.as_strided(shape, {s[0], s[1], dilation * s[2], dilation * s[3], s[2], s[3]},
                         band.storage_offset());
}

// Rows [y0, y0 + rows) of one filtering pass over zero-padded inputs.
torch::Tensor filterBand(const torch::Tensor& padded_image, const torch::Tensor& padded_features,
                         const torch::Tensor& padded_mask, const torch::Tensor& features,
                         const torch::Tensor& bandwidth, const torch::Tensor& centre,
                         int64_t kernel_size, int64_t dilation, int64_t y0, int64_t rows) {
  const int64_t w = features.size(3), k = kernel_size;
  const auto around = [&](const torch::Tensor& padded) {
    return neighbourhoods(padded, k, dilation, y0, rows, w);
  };
  const auto rowsOf = [&](const torch::Tensor& x) { return x.narrow(2, y0, rows).unsqueeze(2); };
  auto difference = around(padded_features) - rowsOf(features).unsqueeze(2);  // (B,D,k,k,r,W)
  // Without autograd the big temporary can be squared in place.
  difference = torch::GradMode::is_enabled() ? difference.square() : difference.mul_(difference);
  const auto distance = difference.sum(1);             // (B,k,k,r,W)
  const auto inside = around(padded_mask).squeeze(1);  // (1,k,k,r,W)
  auto weights = torch::exp(-rowsOf(bandwidth) * distance) * inside;
  auto is_centre = torch::zeros({1, k, k, 1, 1}, weights.options());
  is_centre[0][k / 2][k / 2] = 1.0;
  weights = weights * (1.0 - is_centre) + is_centre * rowsOf(centre);
  weights = weights / weights.sum({1, 2}, true);
  return (around(padded_image) * weights.unsqueeze(1)).sum({2, 3});  // (B,C,r,W)
}

// key=value lines; every lookup failure is a ModelError naming the file.
struct Metadata {
  std::map<std::string, std::string> values;
  std::string source;

  [[noreturn]] void fail(const std::string& problem) const {
    throw ModelError(source + ": " + problem);
  }
  const std::string& text(const std::string& key) const {
    auto it = values.find(key);
    if (it == values.end()) fail("metadata lacks '" + key + "'");
    return it->second;
  }
  int64_t integer(const std::string& key, const std::string& value) const {
    try {
      size_t used = 0;
      const long long parsed = std::stoll(value, &used);
      if (used == value.size()) return parsed;
    } catch (const std::exception&) {
    }
    fail("metadata '" + key + "' is not an integer: " + value);
  }
  int64_t integer(const std::string& key) const { return integer(key, text(key)); }
  std::vector<int64_t> integers(const std::string& key) const {
    std::vector<int64_t> out;
    for (const auto& item : splitList(text(key))) out.push_back(integer(key, item));
    return out;
  }
};

Metadata parseMetadata(const std::string& text, const std::string& source) {
  Metadata metadata{{}, source};
  std::stringstream stream(text);
  std::string line;
  for (int number = 1; std::getline(stream, line); ++number) {
    if (line.empty()) continue;
    const auto eq = line.find('=');
    if (eq == std::string::npos || eq == 0)
      metadata.fail("metadata line " + std::to_string(number) + " is not key=value");
    metadata.values[line.substr(0, eq)] = line.substr(eq + 1);
  }
  return metadata;
}

constexpr const char* kModelKind = "kernel-model";

// (1,C,H,W) planar tensor from an interleaved image.
torch::Tensor planar(const Image& image) {
  auto interleaved = torch::from_blob(const_cast<float*>(image.pixels.data()),
                                      {image.height, image.width, image.channels}, torch::kFloat);
  return interleaved.permute({2, 0, 1}).unsqueeze(0).contiguous();
}

Image interleaved(const torch::Tensor& tensor) {
  const auto hwc = tensor.squeeze(0).permute({1, 2, 0}).contiguous().to(torch::kFloat);
  Image image(int(hwc.size(1)), int(hwc.size(0)), int(hwc.size(2)));
  std::copy_n(hwc.data_ptr<float>(), image.pixels.size(), image.pixels.data());
  return image;
}

}  // namespace

void KernelNetConfig::validate() const {
  if (widths.empty() || widths.size() > 6)
    throw std::invalid_argument("kernel net needs 1 to 6 UNet widths");
  for (auto width : widths)
    if (width < 1 || width > 1024) throw std::invalid_argument("kernel net width out of range");
  if (feature_dims < 1 || feature_dims > 256)
    throw std::invalid_argument("kernel net feature_dims out of range");
  if (dilations.empty() || dilations.size() > 16)
    throw std::invalid_argument("kernel net needs 1 to 16 dilations");
  for (auto dilation : dilations)
    if (dilation < 1 || dilation > 64) throw std::invalid_argument("kernel dilation out of range");
  if (kernel_size < 3 || kernel_size > 15 || kernel_size % 2 == 0)
    throw std::invalid_argument("kernel size must be odd, 3 to 15");
  auxChannels();
  if (demodulate) albedoOffset();
  tonemap::curveFromName(tonemap);
}

int64_t KernelNetConfig::auxChannels() const { return auxChannelCount(input_buffers); }

int64_t KernelNetConfig::albedoOffset() const {
  const auto albedo = std::find(input_buffers.begin(), input_buffers.end(), "albedo");
  if (albedo == input_buffers.end())
    throw std::invalid_argument("kernel net demodulation needs the albedo buffer");
  return auxChannelCount({input_buffers.begin(), albedo});
}

torch::Tensor affinityFilter(const torch::Tensor& image, const torch::Tensor& features,
                             const torch::Tensor& bandwidth, const torch::Tensor& centre,
                             int64_t kernel_size, int64_t dilation, int64_t band_elements) {
  TORCH_CHECK(image.dim() == 4 && features.dim() == 4, "affinityFilter takes (B,C,H,W) tensors");
  const int64_t h = image.size(2), w = image.size(3);
  TORCH_CHECK(features.size(2) == h && features.size(3) == w && bandwidth.size(2) == h &&
                  centre.size(2) == h,
              "affinityFilter: image, features and kernel parameters differ in size");
  const int64_t radius = dilation * (kernel_size / 2);
  const auto pad = F::PadFuncOptions({radius, radius, radius, radius});
  const auto padded_image = F::pad(image, pad);
  const auto padded_features = F::pad(features, pad);
  const auto padded_mask = F::pad(torch::ones({1, 1, h, w}, image.options()), pad);

  const int64_t taps = kernel_size * kernel_size;
  const int64_t per_row = image.size(0) * w * taps * std::max(features.size(1), image.size(1)) + 1;
  const int64_t band = std::clamp<int64_t>(band_elements / per_row, 1, h);
  std::vector<torch::Tensor> bands;
  for (int64_t y0 = 0; y0 < h; y0 += band)
    bands.push_back(filterBand(padded_image, padded_features, padded_mask, features, bandwidth,
                               centre, kernel_size, dilation, y0, std::min(band, h - y0)));
  return bands.size() == 1 ? bands[0] : torch::cat(bands, 2);
}

KernelNetImpl::KernelNetImpl(KernelNetConfig config)
    : config_(std::move(config)), curve_(tonemap::curveFromName(config_.tonemap)) {
  config_.validate();
  const auto& widths = config_.widths;
  int64_t in = 3 + config_.auxChannels();
  for (size_t level = 0; level < widths.size(); ++level) {
    encoders_->push_back(convPair(in, widths[level]));
    in = widths[level];
    if (level + 1 < widths.size()) downsamplers_->push_back(nn::Downsample(widths[level]));
  }
  for (size_t level = widths.size() - 1; level > 0; --level) {
    upsamplers_->push_back(nn::Upsample(widths[level]));
    decoders_->push_back(convPair(widths[level] + widths[level - 1], widths[level - 1]));
  }
  register_module("encoders", encoders_);
  register_module("downsamplers", downsamplers_);
  register_module("upsamplers", upsamplers_);
  register_module("decoders", decoders_);
  head = register_module("head", nn::conv1x1(widths[0], config_.guideChannels()));
  initializeWeights();
}

void KernelNetImpl::initializeWeights() {
  // He initialisation keeps activations (and so the features) at the inputs'
  // scale; PyTorch's default shrinks them layer by layer until all features of
  // a frame nearly coincide and affinity gradients, ~ (f_i - f_j), vanish.
  torch::NoGradGuard no_grad;
  for (auto& module : modules(false))
    if (auto* conv = module->as<torch::nn::Conv2d>()) {
      torch::nn::init::kaiming_normal_(conv->weight, kLeakySlope, torch::kFanIn, torch::kLeakyReLU);
      if (conv->bias.defined()) conv->bias.zero_();
    }
  torch::nn::init::kaiming_normal_(head->weight, 0.0, torch::kFanIn, torch::kLinear);
  // Bandwidth 1 and centre weight exactly 1 when the head input is 0.
  head->bias.zero_();
}

torch::Tensor KernelNetImpl::unet(const torch::Tensor& inputs) {
  std::vector<torch::Tensor> skips;
  torch::Tensor x = inputs;
  const size_t levels = config_.widths.size();
  for (size_t level = 0; level < levels; ++level) {
    x = encoders_[level]->as<torch::nn::Sequential>()->forward(x);
    if (level + 1 < levels) {
      skips.push_back(x);
      x = downsamplers_[level]->as<nn::Downsample>()->forward(x);
    }
  }
  for (size_t i = 0; i + 1 < levels; ++i) {
    x = upsamplers_[i]->as<nn::Upsample>()->forward(x);
    x = torch::cat({x, skips[levels - 2 - i]}, 1);
    x = decoders_[i]->as<torch::nn::Sequential>()->forward(x);
  }
  return head->forward(x);
}

torch::Tensor KernelNetImpl::guideMaps(const torch::Tensor& radiance, const torch::Tensor& aux) {
  TORCH_CHECK(radiance.dim() == 4 && radiance.size(1) == 3, "radiance must be (B,3,H,W)");
  std::vector<torch::Tensor> parts = {tonemapRadiance(radiance, curve_)};
  if (config_.auxChannels() > 0) {
    TORCH_CHECK(aux.defined() && aux.dim() == 4 && aux.size(0) == radiance.size(0) &&
                    aux.size(2) == radiance.size(2) && aux.size(3) == radiance.size(3),
                "aux must be (B,C,H,W) matching the radiance");
    parts.push_back(normalizeAux(aux, config_.input_buffers, curve_));
  }
  const int64_t multiple = int64_t(1) << (config_.widths.size() - 1);
  const auto inputs = nn::padToMultiple(torch::cat(parts, 1), multiple);
  return nn::cropTo(unet(inputs), radiance.size(2), radiance.size(3));
}

std::vector<KernelGuide> KernelNetImpl::decodeGuides(const torch::Tensor& maps) const {
  std::vector<KernelGuide> guides;
  const int64_t d = config_.feature_dims;
  for (size_t i = 0; i < config_.dilations.size(); ++i) {
    const auto slice = maps.narrow(1, int64_t(i) * (d + 2), d + 2);
    const auto raw = slice.narrow(1, 0, d);
    const auto features = raw * torch::rsqrt(raw.square().sum(1, true) + kFeatureNormEps);
    const auto bandwidth =
        kMaxBandwidth * torch::sigmoid(slice.narrow(1, d, 1) - std::log(kMaxBandwidth - 1));
    const auto centre = kMaxCentreWeight * torch::sigmoid(slice.narrow(1, d + 1, 1) -
                                                          std::log(kMaxCentreWeight - 1)) +
                        kMinCentreWeight;
    guides.push_back({features, bandwidth, centre});
  }
  return guides;
}

torch::Tensor KernelNetImpl::forward(const torch::Tensor& radiance, const torch::Tensor& aux) {
  const auto guides = decodeGuides(guideMaps(radiance, aux));
  torch::Tensor x = torch::nan_to_num(radiance, 0.0, 0.0, 0.0).clamp_min(0.0);
  torch::Tensor modulation;
  if (config_.demodulate) {
    const auto albedo = aux.narrow(1, config_.albedoOffset(), 3);
    modulation = torch::nan_to_num(albedo, 0.0, 0.0, 0.0).clamp(0.0, 1.0) + kDemodulationEps;
    x = x / modulation;
  }
  for (size_t i = 0; i < guides.size(); ++i)
    x = affinityFilter(x, guides[i].features, guides[i].bandwidth, guides[i].centre,
                       config_.kernel_size, config_.dilations[i]);
  return config_.demodulate ? x * modulation : x;
}

const char* kernelTaskName(KernelTask task) {
  return task == KernelTask::Cleanse ? "cleanse" : "denoise";
}

KernelTask kernelTaskFromName(const std::string& name) {
  if (name == "cleanse") return KernelTask::Cleanse;
  if (name == "denoise") return KernelTask::Denoise;
  throw std::invalid_argument("unknown task '" + name + "' (cleanse or denoise)");
}

std::string kernelModelInfoToText(const KernelModelInfo& info) {
  const auto& net = info.net;
  std::ostringstream out;
  out << "task=" << kernelTaskName(info.task) << "\n"
      << "input_buffers=" << joinStrings(net.input_buffers) << "\n"
      << "tonemap=" << net.tonemap << "\n"
      << "kernel.widths=" << joinInts(net.widths) << "\n"
      << "kernel.feature_dims=" << net.feature_dims << "\n"
      << "kernel.dilations=" << joinInts(net.dilations) << "\n"
      << "kernel.kernel_size=" << net.kernel_size << "\n"
      << "kernel.demodulate=" << (net.demodulate ? 1 : 0) << "\n"
      << "kernel.centre_weight=" << kCentreWeightParametrisation << "\n";
  for (const auto& [key, value] : info.notes) {
    if (value.find('\n') != std::string::npos || key.find('=') != std::string::npos ||
        key.find('\n') != std::string::npos)
      throw std::invalid_argument("model note '" + key + "' must be one line, no '=' in its key");
    out << "note." << key << "=" << value << "\n";
  }
  return out.str();
}

KernelModelInfo kernelModelInfoFromText(const std::string& text, const std::string& source) {
  const Metadata metadata = parseMetadata(text, source);
  KernelModelInfo info;
  auto& net = info.net;
  net.input_buffers = splitList(metadata.text("input_buffers"));
  net.tonemap = metadata.text("tonemap");
  net.widths = metadata.integers("kernel.widths");
  net.feature_dims = metadata.integer("kernel.feature_dims");
  net.dilations = metadata.integers("kernel.dilations");
  net.kernel_size = metadata.integer("kernel.kernel_size");
  // Models written before demodulation existed filter the radiance itself.
  const bool has_demodulate = metadata.values.count("kernel.demodulate") > 0;
  if (has_demodulate) {
    const int64_t demodulate = metadata.integer("kernel.demodulate");
    if (demodulate != 0 && demodulate != 1)
      metadata.fail("metadata 'kernel.demodulate' is not 0 or 1");
    net.demodulate = demodulate == 1;
  }
  // The centre weight was once softplus(raw) / ln 2, unbounded; the same weights
  // read through the bounded sigmoid give a different filter. Files that name
  // their parametrisation, or that have the later demodulate key, are bounded;
  // older files are ambiguous and refused rather than silently misread.
  if (metadata.values.count("kernel.centre_weight")) {
    if (metadata.text("kernel.centre_weight") != kCentreWeightParametrisation)
      metadata.fail("metadata 'kernel.centre_weight' is '" + metadata.text("kernel.centre_weight") +
                    "'; this build reads only '" + kCentreWeightParametrisation + "'");
  } else if (!has_demodulate) {
    metadata.fail(
        "written before the bounded centre weight (no 'kernel.centre_weight' key); "
        "this build would misread it, retrain the model with dncleanse train");
  }
  try {
    info.task = kernelTaskFromName(metadata.text("task"));
    net.validate();
  } catch (const std::invalid_argument& error) {
    metadata.fail(error.what());
  }
  for (const auto& [key, value] : metadata.values)
    if (key.rfind("note.", 0) == 0) info.notes[key.substr(5)] = value;
  return info;
}

void saveKernelModel(const std::string& path, const KernelModelInfo& info, KernelNet& net) {
  torch::serialize::OutputArchive archive;
  net->save(archive);
  writeArchiveFile(path, kModelKind, kernelModelInfoToText(info), archive);
}

LoadedKernelModel loadKernelModel(const std::string& path) {
  auto file = readArchiveFile(path, kModelKind);
  LoadedKernelModel loaded;
  loaded.info = kernelModelInfoFromText(file.text, path);
  loaded.net = KernelNet(loaded.info.net);
  loadModuleWeights(*loaded.net, file.archive, path);
  loaded.net->eval();
  return loaded;
}

std::vector<std::string> requiredBuffers(const KernelNetConfig& config) {
  std::vector<std::string> names = {"color"};
  names.insert(names.end(), config.input_buffers.begin(), config.input_buffers.end());
  return names;
}

Image runKernelNet(KernelNet& net, const FrameBuffers& frame) {
  torch::NoGradGuard no_grad;
  net->eval();
  const Image& color = frame.get("color");
  auto radiance = planar(color).narrow(1, 0, 3);
  std::vector<torch::Tensor> aux;
  for (const auto& name : net->config().input_buffers) aux.push_back(planar(frame.get(name)));
  const auto aux_tensor = aux.empty() ? torch::Tensor() : torch::cat(aux, 1);
  return interleaved(net->forward(radiance, aux_tensor));
}

}  // namespace dn
