// General building blocks of convolutional denoisers: timestep embeddings,
// residual blocks with scale-shift conditioning, self-attention, resampling.
// Used by the diffusion UNet and the kernel-predicting networks.
#pragma once

#include <cstdint>

#include <torch/torch.h>

namespace dn::nn {

// Sinusoidal embedding of (possibly fractional) timesteps t of shape (B):
// [cos(t f_0..f_{d/2-1}), sin(t f_0..)], f_i = max_period^(-i / (d/2)). Shape (B, dim).
torch::Tensor timestepEmbedding(const torch::Tensor& t, int64_t dim, double max_period = 10000.0);

// The largest group count <= preferred that divides channels (GroupNorm needs it).
int64_t groupCount(int64_t channels, int64_t preferred);

// Sets every parameter of a module to zero: "zero convolutions" and output layers
// that start as the identity of a residual path.
void zeroParameters(torch::nn::Module& module);

torch::nn::Conv2d conv3x3(int64_t in, int64_t out, int64_t stride = 1, int64_t dilation = 1);
torch::nn::Conv2d conv1x1(int64_t in, int64_t out);

// A 1x1 convolution with Conv2d's parameter names, shapes and initialisation
// that always runs on oneDNN. LibTorch 1.13 sends 1x1 convolutions of batches
// under 16 on one thread to an im2col + BLAS path, and Debian links reference
// (netlib) BLAS: there they took over half of a training step.
struct PointwiseConvImpl : torch::nn::Module {
  PointwiseConvImpl(int64_t in, int64_t out);
  torch::Tensor forward(const torch::Tensor& x);
  torch::Tensor weight, bias;
};
TORCH_MODULE(PointwiseConv);

// Maps a timestep embedding of `base_channels` to `embedding_channels` (Linear, SiLU, Linear).
struct TimestepMlpImpl : torch::nn::Module {
  TimestepMlpImpl(int64_t base_channels, int64_t embedding_channels);
  torch::Tensor forward(const torch::Tensor& t);  // t: (B) timesteps

  int64_t base_channels;
  torch::nn::Linear fc1{nullptr}, fc2{nullptr};
};
TORCH_MODULE(TimestepMlp);

// GroupNorm, SiLU, conv3x3, [scale-shift by an embedding], GroupNorm, SiLU, conv3x3,
// plus a (1x1 when the width changes) skip. embedding_channels == 0 builds an
// unconditioned block; the second conv starts at zero so the block starts as its skip.
struct ResBlockImpl : torch::nn::Module {
  ResBlockImpl(int64_t in_channels, int64_t out_channels, int64_t embedding_channels,
               int64_t norm_groups, int64_t dilation = 1);
  torch::Tensor forward(const torch::Tensor& x, const torch::Tensor& embedding = {});

  torch::nn::GroupNorm norm1{nullptr}, norm2{nullptr};
  torch::nn::Conv2d conv1{nullptr}, conv2{nullptr};
  PointwiseConv skip{nullptr};
  torch::nn::Linear embedding_proj{nullptr};
};
TORCH_MODULE(ResBlock);

// Multi-head self-attention over all pixels with a residual connection. Queries
// are processed in chunks so large images stay within memory.
struct AttentionBlockImpl : torch::nn::Module {
  AttentionBlockImpl(int64_t channels, int64_t head_channels, int64_t norm_groups);
  torch::Tensor forward(const torch::Tensor& x);

  int64_t heads;
  torch::nn::GroupNorm norm{nullptr};
  PointwiseConv qkv{nullptr}, proj{nullptr};
};
TORCH_MODULE(AttentionBlock);

// Stride-2 3x3 convolution.
struct DownsampleImpl : torch::nn::Module {
  explicit DownsampleImpl(int64_t channels);
  torch::Tensor forward(const torch::Tensor& x) { return conv->forward(x); }
  torch::nn::Conv2d conv{nullptr};
};
TORCH_MODULE(Downsample);

// Nearest-neighbour 2x upsampling followed by a 3x3 convolution.
struct UpsampleImpl : torch::nn::Module {
  explicit UpsampleImpl(int64_t channels);
  torch::Tensor forward(const torch::Tensor& x);
  torch::nn::Conv2d conv{nullptr};
};
TORCH_MODULE(Upsample);

// Reflect-pads H and W up to a multiple of `multiple`; cropTo undoes it.
torch::Tensor padToMultiple(const torch::Tensor& x, int64_t multiple);
torch::Tensor cropTo(const torch::Tensor& x, int64_t height, int64_t width);

}  // namespace dn::nn
