#include "dn/nn/oidn_unet.h"

#include <algorithm>
#if defined(__x86_64__)
#include <cpuid.h>
#endif
#include <stdexcept>
#include <utility>

namespace dn {
namespace {

// Channel widths of OIDN's training/model.py, per size.
struct Widths {
  int64_t ec1, ec2, ec3, ec4, ec5, dc4, dc3, dc2a, dc2b, dc1a, dc1b;
};
Widths widthsOf(OidnArch arch) {
  switch (arch) {
    case OidnArch::Small:
      return {32, 32, 32, 32, 32, 64, 64, 64, 32, 32, 32};
    case OidnArch::Large:
      return {64, 96, 128, 192, 256, 192, 128, 96, 96, 64, 64};
    default:
      return {32, 48, 64, 80, 96, 112, 96, 64, 64, 64, 32};
  }
}

// Nearest 2x upsampling followed by a 3x3 convolution is, for each of the four
// output pixel phases, a 2x2 convolution of the coarse input: the taps that
// land on the same coarse pixel add up. Along one axis, even outputs see the
// coarse offsets {-1, 0} with taps {w0, w1 + w2}, odd outputs {0, +1} with
// {w0 + w1, w2}. (O, I, 3, 3) -> (4 O, I, 2, 2), output groups ordered by
// phase (row, column): 16 instead of 36 multiply-adds per coarse pixel.
torch::Tensor foldUpsampling(const torch::Tensor& weight) {
  const torch::Tensor taps =
      torch::tensor({1, 0, 0, 0, 1, 1, 1, 1, 0, 0, 0, 1}, weight.options()).view({2, 2, 3});
  return torch::einsum("pak,oikl,qbl->pqoiab", {taps, weight, taps})
      .reshape({4 * weight.size(0), weight.size(1), 2, 2});
}

}  // namespace

const char* oidnArchName(OidnArch arch) {
  switch (arch) {
    case OidnArch::Small:
      return "small";
    case OidnArch::Large:
      return "large";
    default:
      return "default";
  }
}

OidnArch oidnArchFromName(const std::string& name) {
  for (OidnArch arch : {OidnArch::Default, OidnArch::Small, OidnArch::Large})
    if (name == oidnArchName(arch)) return arch;
  throw std::invalid_argument("unknown OIDN network size '" + name +
                              "' (expected default, small or large)");
}

std::vector<OidnConv> oidnConvs(const OidnUNetConfig& c) {
  const Widths w = widthsOf(c.arch);
  const int64_t ic = c.in_channels, oc = c.out_channels;
  if (c.arch == OidnArch::Large)
    return {{"enc_conv1a", ic, w.ec1},
            {"enc_conv1b", w.ec1, w.ec1},
            {"enc_conv2a", w.ec1, w.ec2},
            {"enc_conv2b", w.ec2, w.ec2},
            {"enc_conv3a", w.ec2, w.ec3},
            {"enc_conv3b", w.ec3, w.ec3},
            {"enc_conv4a", w.ec3, w.ec4},
            {"enc_conv4b", w.ec4, w.ec4},
            {"enc_conv5a", w.ec4, w.ec5},
            {"enc_conv5b", w.ec5, w.ec5},
            {"dec_conv4a", w.ec5 + w.ec3, w.dc4},
            {"dec_conv4b", w.dc4, w.dc4},
            {"dec_conv3a", w.dc4 + w.ec2, w.dc3},
            {"dec_conv3b", w.dc3, w.dc3},
            {"dec_conv2a", w.dc3 + w.ec1, w.dc2a},
            {"dec_conv2b", w.dc2a, w.dc2b},
            {"dec_conv1a", w.dc2b + ic, w.dc1a},
            {"dec_conv1b", w.dc1a, w.dc1b},
            {"dec_conv1c", w.dc1b, oc}};
  return {{"enc_conv0", ic, w.ec1},       {"enc_conv1", w.ec1, w.ec1},
          {"enc_conv2", w.ec1, w.ec2},    {"enc_conv3", w.ec2, w.ec3},
          {"enc_conv4", w.ec3, w.ec4},    {"enc_conv5a", w.ec4, w.ec5},
          {"enc_conv5b", w.ec5, w.ec5},   {"dec_conv4a", w.ec5 + w.ec3, w.dc4},
          {"dec_conv4b", w.dc4, w.dc4},   {"dec_conv3a", w.dc4 + w.ec2, w.dc3},
          {"dec_conv3b", w.dc3, w.dc3},   {"dec_conv2a", w.dc3 + w.ec1, w.dc2a},
          {"dec_conv2b", w.dc2a, w.dc2b}, {"dec_conv1a", w.dc2b + ic, w.dc1a},
          {"dec_conv1b", w.dc1a, w.dc1b}, {"dec_conv0", w.dc1b, oc}};
}

OidnConv3x3Impl::OidnConv3x3Impl(int64_t in, int64_t out, bool initialise) {
  if (initialise) {  // torch::nn::Conv2d's own initialisation, random stream and all
    torch::nn::Conv2d conv(torch::nn::Conv2dOptions(in, out, 3).padding(1));
    weight = conv->weight.detach();
    bias = conv->bias.detach();
  } else {
    weight = torch::empty({out, in, 3, 3});
    bias = torch::empty({out});
  }
  weight = register_parameter("weight", weight);
  bias = register_parameter("bias", bias);
}

OidnUNetImpl::OidnUNetImpl(const OidnUNetConfig& config) : config_(config) {
  if (config.in_channels < 1 || config.out_channels < 1)
    throw std::invalid_argument("OIDN network needs at least one input and output channel");
  for (const OidnConv& c : oidnConvs(config)) {
    if (config.encoder_only && c.name.rfind("enc_", 0) != 0) continue;
    convs_.emplace(c.name, register_module(c.name, OidnConv3x3(c.in, c.out, config.initialise)));
  }
  if (config.arch == OidnArch::Large) {
    encoder_ = {{"enc_conv1a", "enc_conv1b"},
                {"enc_conv2a", "enc_conv2b"},
                {"enc_conv3a", "enc_conv3b"},
                {"enc_conv4a", "enc_conv4b"}};
    decoder_ = {{"dec_conv4a", "dec_conv4b"},
                {"dec_conv3a", "dec_conv3b"},
                {"dec_conv2a", "dec_conv2b"},
                {"dec_conv1a", "dec_conv1b", "dec_conv1c"}};
  } else {
    encoder_ = {{"enc_conv0", "enc_conv1"}, {"enc_conv2"}, {"enc_conv3"}, {"enc_conv4"}};
    decoder_ = {{"dec_conv4a", "dec_conv4b"},
                {"dec_conv3a", "dec_conv3b"},
                {"dec_conv2a", "dec_conv2b"},
                {"dec_conv1a", "dec_conv1b", "dec_conv0"}};
  }
  bottleneck_ = {"enc_conv5a", "enc_conv5b"};
}

void OidnUNetImpl::useInnerPrecision(torch::ScalarType type) {
  if (type != torch::kFloat && type != torch::kBFloat16 && type != torch::kHalf)
    throw std::invalid_argument(std::string("OIDN network: no inner precision ") +
                                c10::toString(type) + " (float, bfloat16 or half)");
  if (type == inner_) return;  // the copies stay: each is remade when its weight changes
  inner_ = type;
  reduced_.clear();
  folded_.clear();
}

bool OidnUNetImpl::inReducedPrecision(const std::string& name) const {
  // The first and the output convolution stay in float: the input and the
  // result are not rounded to bfloat16's 8-bit mantissa (with them in
  // bfloat16 a clean frame lost 0.4 dB). They are cheap: 9 input, 3 output channels.
  return inner_ != torch::kFloat && name != oidnConvs(config_).front().name &&
         name != oidnConvs(config_).back().name;
}

namespace {

// Tensors made in inference mode (weights moved to a GPU there) have no
// version counter; their storage is what tells them apart.
int64_t versionOf(const torch::Tensor& t) { return t.is_inference() ? 0 : t._version(); }

// Whether `derived` was made from `source` as it is now, in `type` on its device.
bool upToDate(const torch::Tensor& derived, const void* madeFrom, int64_t version,
              const torch::Tensor& source, torch::ScalarType type) {
  return derived.defined() && madeFrom == source.data_ptr() && version == versionOf(source) &&
         derived.scalar_type() == type && derived.device() == source.device();
}

}  // namespace

OidnUNetImpl::Weights OidnUNetImpl::weights(const std::string& name) {
  const OidnConv3x3& c = convs_.at(name);
  if (!inReducedPrecision(name)) return {c->weight, c->bias};
  Derived& d = reduced_[name];
  if (!upToDate(d.weights.weight, d.source, d.version, c->weight, inner_)) {
    d.weights = {c->weight.to(inner_), c->bias.to(inner_)};
    d.source = c->weight.data_ptr();
    d.version = versionOf(c->weight);
  }
  return d.weights;
}

torch::Tensor OidnUNetImpl::foldedWeight(const std::string& name, int64_t coarseChannels,
                                         torch::MemoryFormat format) {
  const OidnConv3x3& c = convs_.at(name);
  const torch::ScalarType type = inReducedPrecision(name) ? inner_ : torch::kFloat;
  Derived& d = folded_[name];
  // Folded while the weights train would keep a stale copy: only reused
  // where no gradient flows (inference, the frozen base).
  const bool reusable = !torch::GradMode::is_enabled() || !c->weight.requires_grad();
  if (!reusable || !upToDate(d.weights.weight, d.source, d.version, c->weight, type) ||
      !d.weights.weight.is_contiguous(format)) {
    const torch::Tensor weight = weights(name).weight;
    d.weights.weight = foldUpsampling(weight.narrow(1, 0, coarseChannels)).contiguous(format);
    d.source = c->weight.data_ptr();
    d.version = versionOf(c->weight);
    if (!reusable) return std::exchange(d.weights.weight, torch::Tensor());
  }
  return d.weights.weight;
}

torch::Tensor OidnUNetImpl::conv(const std::string& name, const torch::Tensor& x) {
  const Weights p = weights(name);
  return torch::conv2d(x.to(p.weight.scalar_type()), p.weight, p.bias, 1, 1).relu_();
}

torch::Tensor OidnUNetImpl::upConv(const std::string& name, const torch::Tensor& coarse,
                                   const torch::Tensor& skip) {
  const OidnConv3x3& c = convs_.at(name);
  const Weights p = weights(name);
  const auto type = p.weight.scalar_type();
  const int64_t batch = coarse.size(0), ch = coarse.size(1), h = coarse.size(2), w = coarse.size(3);
  const int64_t outCh = p.weight.size(0);
  const auto format = coarse.suggest_memory_format();
  // The skip's share of the convolution, at the fine resolution, with the bias.
  // The network's input, the last skip, stays in float as the first convolution.
  const bool skipInFloat = skip.scalar_type() == torch::kFloat;
  torch::Tensor out =
      skipInFloat
          ? torch::conv2d(skip, c->weight.narrow(1, ch, skip.size(1)), c->bias, 1, 1)
          : torch::conv2d(skip.to(type), p.weight.narrow(1, ch, skip.size(1)), p.bias, 1, 1);
  // The upsampled share: each phase from the coarse input, padded by one so
  // that phase (py, px) is the window starting at (py, px). One phase at a
  // time: at full resolution the four at once were the network's peak memory.
  const torch::Tensor folded = foldedWeight(name, ch, format);
  const torch::Tensor input = coarse.to(type);
  const torch::Tensor fine = out.view({batch, outCh, h, 2, w, 2});
  for (int64_t py = 0; py < 2; ++py)
    for (int64_t px = 0; px < 2; ++px) {
      const torch::Tensor phase =
          torch::conv2d(input, folded.narrow(0, (2 * py + px) * outCh, outCh), {}, 1, 1);
      fine.select(3, py).select(4, px).add_(phase.narrow(2, py, h).narrow(3, px, w));
    }
  return out.relu_();
}

torch::Tensor OidnUNetImpl::forward(const torch::Tensor& input, const ControlResiduals* residuals) {
  return decode(encode(input), residuals).to(input.scalar_type());
}

OidnUNetImpl::Features OidnUNetImpl::encode(const torch::Tensor& input) {
  // Skips: the input, then every pooled level but the last, which only feeds
  // the bottleneck.
  Features f;
  f.skips = {input};
  torch::Tensor x = input;
  for (const auto& level : encoder_) {
    for (const auto& name : level) x = conv(name, x);
    x = torch::max_pool2d(x, 2, 2);
    f.skips.push_back(x);
  }
  f.skips.pop_back();
  std::reverse(f.skips.begin(), f.skips.end());
  for (const auto& name : bottleneck_) x = conv(name, x);
  f.bottleneck = x;
  return f;
}

torch::Tensor OidnUNetImpl::decode(const Features& features, const ControlResiduals* residuals) {
  if (config_.encoder_only) throw std::logic_error("an encoder-only OIDN network has no decoder");
  torch::Tensor x = features.bottleneck;
  if (residuals) x = x + residuals->middle;
  for (size_t level = 0; level < decoder_.size(); ++level) {
    torch::Tensor skip = features.skips[level];
    if (residuals) skip = skip + residuals->skips[level];
    const auto& names = decoder_[level];
    x = upConv(names.front(), x, skip);
    for (size_t i = 1; i < names.size(); ++i) x = conv(names[i], x);
  }
  return x;
}

std::vector<int64_t> OidnUNetImpl::skipChannels() const {
  const Widths w = widthsOf(config_.arch);
  return {w.ec3, w.ec2, w.ec1, config_.in_channels};
}

int64_t OidnUNetImpl::bottleneckChannels() const { return widthsOf(config_.arch).ec5; }

const std::vector<OidnInputSet>& oidnInputSets() {
  static const std::vector<OidnInputSet> sets = {
      {"hdr", {"color"}},
      {"hdr_alb", {"color", "albedo"}},
      {"hdr_alb_nrm", {"color", "albedo", "normal"}},
      {"hdr_calb_cnrm_large", {"color", "albedo", "normal"}, true, true},
      {"alb", {"albedo"}},
      {"nrm", {"normal"}}};
  return sets;
}

const OidnInputSet& oidnInputSet(const std::string& name) {
  for (const auto& set : oidnInputSets())
    if (set.name == name) return set;
  throw std::invalid_argument(
      "unknown OIDN input set '" + name +
      "' (expected hdr, hdr_alb, hdr_alb_nrm, hdr_calb_cnrm_large, alb or nrm)");
}

OidnBaseImpl::OidnBaseImpl(OidnArch arch, const std::vector<std::string>& inputSets,
                           bool initialise)
    : sets_(inputSets) {
  if (sets_.empty()) throw std::invalid_argument("the OIDN base needs at least one input set");
  for (const auto& name : sets_) {
    const OidnInputSet& set = oidnInputSet(name);
    if (nets_.count(name)) throw std::invalid_argument("OIDN input set '" + name + "' given twice");
    const OidnArch netArch = set.large ? OidnArch::Large : arch;
    nets_.emplace(name, register_module(name, OidnUNet(OidnUNetConfig{netArch, set.channels(), 3,
                                                                      false, initialise})));
  }
}

std::pair<OidnUNet, const OidnInputSet*> OidnBaseImpl::pick(
    const std::vector<std::string>& available) const {
  const OidnInputSet* set = pickSet(available);
  return {set ? net(set->name) : OidnUNet(nullptr), set};
}

const OidnInputSet* OidnBaseImpl::pickSet(const std::vector<std::string>& available) const {
  auto has = [&](const std::string& b) {
    return std::find(available.begin(), available.end(), b) != available.end();
  };
  const OidnInputSet* best = nullptr;
  for (const auto& set : oidnInputSets())
    if (set.denoised() == "color" && !set.cleanAux && nets_.count(set.name) &&
        std::all_of(set.buffers.begin(), set.buffers.end(), has))
      best = &set;  // sets are listed poorest first
  return best;
}

bool OidnBaseImpl::canPrefilter() const {
  return nets_.count("alb") && nets_.count("nrm") && nets_.count("hdr_calb_cnrm_large");
}

OidnUNet OidnBaseImpl::net(const std::string& inputSet) const {
  OidnUNet net = nets_.at(inputSet);
  if (channelsLast_) net->useChannelsLast();
  return net;
}

void OidnBaseImpl::useInnerPrecision(torch::ScalarType type) {
  for (auto& [name, net] : nets_) net->useInnerPrecision(type);
}

bool cpuHasBFloat16Matrix() {
#if defined(__x86_64__)
  unsigned eax = 0, ebx = 0, ecx = 0, edx = 0;
  if (!__get_cpuid_count(7, 0, &eax, &ebx, &ecx, &edx)) return false;
  return (edx >> 22) & 1;  // AMX-BF16
#else
  return false;
#endif
}

void OidnUNetImpl::useChannelsLast() {
  if (channelsLast_) return;
  c10::InferenceMode normalTensors(false);  // weights, even when first used in inference mode
  torch::NoGradGuard noGrad;
  for (auto& p : parameters())
    if (p.dim() == 4) p.set_data(p.contiguous(torch::MemoryFormat::ChannelsLast));
  channelsLast_ = true;
}

}  // namespace dn
