#include "dn/nn/nn_blocks.h"

#include <cmath>

namespace dn::nn {
namespace {

constexpr int64_t kAttentionChunkElements = int64_t(1) << 24;  // 64 MiB of fp32 scores

}  // namespace

torch::Tensor timestepEmbedding(const torch::Tensor& t, int64_t dim, double max_period) {
  const int64_t half = dim / 2;
  auto exponents = torch::arange(half, torch::kFloat) / double(half);
  auto freqs = torch::exp(-std::log(max_period) * exponents).to(t.device());
  auto args = t.to(torch::kFloat).unsqueeze(1) * freqs.unsqueeze(0);
  auto embedding = torch::cat({torch::cos(args), torch::sin(args)}, 1);
  if (dim % 2 == 1)
    embedding =
        torch::nn::functional::pad(embedding, torch::nn::functional::PadFuncOptions({0, 1}));
  return embedding;
}

int64_t groupCount(int64_t channels, int64_t preferred) {
  for (int64_t groups = std::min(channels, preferred); groups > 1; --groups)
    if (channels % groups == 0) return groups;
  return 1;
}

void zeroParameters(torch::nn::Module& module) {
  torch::NoGradGuard no_grad;
  for (auto& parameter : module.parameters()) parameter.zero_();
}

torch::nn::Conv2d conv3x3(int64_t in, int64_t out, int64_t stride, int64_t dilation) {
  return torch::nn::Conv2d(
      torch::nn::Conv2dOptions(in, out, 3).stride(stride).padding(dilation).dilation(dilation));
}

torch::nn::Conv2d conv1x1(int64_t in, int64_t out) {
  return torch::nn::Conv2d(torch::nn::Conv2dOptions(in, out, 1));
}

PointwiseConvImpl::PointwiseConvImpl(int64_t in, int64_t out) {
  auto reference = conv1x1(in, out);  // for Conv2d's exact initialisation
  weight = register_parameter("weight", reference->weight.detach().clone());
  bias = register_parameter("bias", reference->bias.detach().clone());
}

torch::Tensor PointwiseConvImpl::forward(const torch::Tensor& x) {
  // Dilation does not change a 1x1 convolution, but it makes LibTorch choose
  // oneDNN for the forward and backward pass instead of its BLAS-based path.
  namespace F = torch::nn::functional;
  return F::conv2d(x, weight, F::Conv2dFuncOptions().bias(bias).dilation(2));
}

TimestepMlpImpl::TimestepMlpImpl(int64_t base_channels_, int64_t embedding_channels)
    : base_channels(base_channels_) {
  fc1 = register_module("fc1", torch::nn::Linear(base_channels, embedding_channels));
  fc2 = register_module("fc2", torch::nn::Linear(embedding_channels, embedding_channels));
}

torch::Tensor TimestepMlpImpl::forward(const torch::Tensor& t) {
  return fc2->forward(torch::silu(fc1->forward(timestepEmbedding(t, base_channels))));
}

ResBlockImpl::ResBlockImpl(int64_t in_channels, int64_t out_channels, int64_t embedding_channels,
                           int64_t norm_groups, int64_t dilation) {
  using torch::nn::GroupNormOptions;
  norm1 = register_module("norm1", torch::nn::GroupNorm(GroupNormOptions(
                                       groupCount(in_channels, norm_groups), in_channels)));
  conv1 = register_module("conv1", conv3x3(in_channels, out_channels, 1, dilation));
  norm2 = register_module("norm2", torch::nn::GroupNorm(GroupNormOptions(
                                       groupCount(out_channels, norm_groups), out_channels)));
  conv2 = register_module("conv2", conv3x3(out_channels, out_channels, 1, dilation));
  zeroParameters(*conv2);
  if (embedding_channels > 0)
    embedding_proj =
        register_module("embedding_proj", torch::nn::Linear(embedding_channels, 2 * out_channels));
  if (in_channels != out_channels)
    skip = register_module("skip", PointwiseConv(in_channels, out_channels));
}

torch::Tensor ResBlockImpl::forward(const torch::Tensor& x, const torch::Tensor& embedding) {
  auto h = conv1->forward(torch::silu(norm1->forward(x)));
  h = norm2->forward(h);
  if (embedding_proj && embedding.defined()) {
    auto scale_shift = embedding_proj->forward(torch::silu(embedding)).unsqueeze(-1).unsqueeze(-1);
    auto parts = scale_shift.chunk(2, 1);
    h = h * (1 + parts[0]) + parts[1];
  }
  h = conv2->forward(torch::silu(h));
  return (skip ? skip->forward(x) : x) + h;
}

AttentionBlockImpl::AttentionBlockImpl(int64_t channels, int64_t head_channels, int64_t norm_groups)
    : heads(std::max<int64_t>(1, channels / head_channels)) {
  TORCH_CHECK(channels % heads == 0, "attention channels must split evenly into heads");
  norm = register_module("norm", torch::nn::GroupNorm(torch::nn::GroupNormOptions(
                                     groupCount(channels, norm_groups), channels)));
  qkv = register_module("qkv", PointwiseConv(channels, 3 * channels));
  proj = register_module("proj", PointwiseConv(channels, channels));
  zeroParameters(*proj);
}

torch::Tensor AttentionBlockImpl::forward(const torch::Tensor& x) {
  const auto b = x.size(0), c = x.size(1), h = x.size(2), w = x.size(3);
  const int64_t n = h * w, d = c / heads;
  auto parts = qkv->forward(norm->forward(x)).reshape({b * heads, 3 * d, n}).chunk(3, 1);
  const double scale = 1.0 / std::sqrt(double(d));
  auto queries = (parts[0] * scale).transpose(1, 2);  // (BH, N, d)
  auto keys = parts[1];                               // (BH, d, N)
  auto values = parts[2].transpose(1, 2);             // (BH, N, d)
  const int64_t chunk =
      std::max<int64_t>(1, kAttentionChunkElements / std::max<int64_t>(1, n * b * heads));
  std::vector<torch::Tensor> outputs;
  for (int64_t start = 0; start < n; start += chunk) {
    auto q = queries.narrow(1, start, std::min(chunk, n - start));
    outputs.push_back(torch::bmm(torch::softmax(torch::bmm(q, keys), -1), values));
  }
  auto attended = (outputs.size() == 1 ? outputs[0] : torch::cat(outputs, 1)).transpose(1, 2);
  return x + proj->forward(attended.reshape({b, c, h, w}));
}

DownsampleImpl::DownsampleImpl(int64_t channels) {
  conv = register_module("conv", conv3x3(channels, channels, 2));
}

UpsampleImpl::UpsampleImpl(int64_t channels) {
  conv = register_module("conv", conv3x3(channels, channels));
}

torch::Tensor UpsampleImpl::forward(const torch::Tensor& x) {
  namespace F = torch::nn::functional;
  auto up = F::interpolate(x, F::InterpolateFuncOptions()
                                  .scale_factor(std::vector<double>{2.0, 2.0})
                                  .mode(torch::kNearest));
  return conv->forward(up);
}

torch::Tensor padToMultiple(const torch::Tensor& x, int64_t multiple) {
  const int64_t h = x.size(-2), w = x.size(-1);
  const int64_t pad_h = (multiple - h % multiple) % multiple;
  const int64_t pad_w = (multiple - w % multiple) % multiple;
  if (pad_h == 0 && pad_w == 0) return x;
  namespace F = torch::nn::functional;
  // Reflection needs the pad smaller than the size; replicate covers tiny images.
  auto options = F::PadFuncOptions({0, pad_w, 0, pad_h});
  if (pad_h < h && pad_w < w) return F::pad(x, options.mode(torch::kReflect));
  return F::pad(x, options.mode(torch::kReplicate));
}

torch::Tensor cropTo(const torch::Tensor& x, int64_t height, int64_t width) {
  if (x.size(-2) == height && x.size(-1) == width) return x;
  return x.narrow(-2, 0, height).narrow(-1, 0, width);
}

}  // namespace dn::nn
