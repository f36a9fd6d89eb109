// Host <-> device copies of float buffers through page-locked staging memory.
// A copy from ordinary (pageable) memory to a GPU goes through the driver's
// own bounce buffer at about 4.5 GB/s (an H200's host, bench/gpu/README.md);
// from page-locked memory the device reads at full speed and the host moves
// on at once, so the slow part left is the host's memcpy into it, which
// several threads share.
#pragma once

#include <cstddef>

#include <torch/torch.h>

namespace dn {

// memcpy of `bytes` in slices of at least 1 MiB over LibTorch's CPU threads
// (its warm pool: no thread started per buffer); one slice on one thread.
void parallelCopy(void* to, const void* from, std::size_t bytes);

// A CPU float tensor of `sizes` holding a copy of `data`, made by
// parallelCopy; in page-locked memory where `pinned` (CUDA LibTorch only).
// Pinned blocks come from LibTorch's caching host allocator: one freed after
// an asynchronous copy is handed out again only once the device has read
// it, so the next frame of the same size reuses it without cudaHostAlloc.
torch::Tensor stagedCopy(const float* data, at::IntArrayRef sizes, bool pinned);

// A copy of `data` (C order, of `sizes`) as a float tensor on `device`. On
// CUDA through pinned staging and an asynchronous copy (ordered on the
// current stream before any later work there); on the CPU stagedCopy.
torch::Tensor floatsToDevice(const float* data, at::IntArrayRef sizes, torch::Device device);

// The contiguous float tensor `source`, on any device, into `to` (its numel
// floats); from CUDA through pinned staging, waiting for the device.
void floatsToHost(const torch::Tensor& source, float* to);

}  // namespace dn
