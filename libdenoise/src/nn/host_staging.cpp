#include "dn/nn/host_staging.h"

#include <ATen/Parallel.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <stdexcept>

namespace dn {

namespace {

// Below this handing a slice to another thread costs more than it saves.
constexpr std::size_t kSliceBytes = std::size_t(1) << 20;

}  // namespace

void parallelCopy(void* to, const void* from, std::size_t bytes) {
  const std::size_t slices = std::max<std::size_t>(1, bytes / kSliceBytes);
  auto* out = static_cast<char*>(to);
  const auto* in = static_cast<const char*>(from);
  // Slice s covers [s bytes / slices, (s + 1) bytes / slices): every byte once.
  at::parallel_for(0, int64_t(slices), 1, [&](int64_t first, int64_t last) {
    const std::size_t begin = bytes * std::size_t(first) / slices;
    const std::size_t end = bytes * std::size_t(last) / slices;
    std::memcpy(out + begin, in + begin, end - begin);
  });
}

torch::Tensor stagedCopy(const float* data, at::IntArrayRef sizes, bool pinned) {
  torch::Tensor staging =
      torch::empty(sizes, torch::TensorOptions().dtype(torch::kFloat).pinned_memory(pinned));
  parallelCopy(staging.data_ptr<float>(), data, staging.nbytes());
  return staging;
}

torch::Tensor floatsToDevice(const float* data, at::IntArrayRef sizes, torch::Device device) {
  if (device.is_cpu()) return stagedCopy(data, sizes, false);  // a copy, as on any device
  if (!device.is_cuda()) return torch::from_blob(const_cast<float*>(data), sizes).to(device);
  return stagedCopy(data, sizes, true).to(device, /*non_blocking=*/true);
}

void floatsToHost(const torch::Tensor& source, float* to) {
  if (source.scalar_type() != torch::kFloat || !source.is_contiguous())
    throw std::invalid_argument("floatsToHost: a contiguous float tensor");
  torch::Tensor host = source;
  if (source.is_cuda()) {
    host = torch::empty(source.sizes(),
                        torch::TensorOptions().dtype(torch::kFloat).pinned_memory(true));
    host.copy_(source);  // waits for the device
  } else if (!source.is_cpu()) {
    host = source.cpu();
  }
  parallelCopy(to, host.data_ptr<float>(), host.nbytes());
}

}  // namespace dn
