#include "dn/infer/device.h"

#include <algorithm>
#include <stdexcept>

#if DN_WITH_CUDA
#include <c10/cuda/CUDACachingAllocator.h>
#include <c10/cuda/CUDAGuard.h>
#include <cuda_runtime_api.h>
#endif

namespace dn {

torch::Device parseDevice(const std::string& name) {
  if (name != "cpu" && name.rfind("cuda", 0) != 0)
    throw std::invalid_argument("device '" + name + "': expected cpu, cuda or cuda:N");
  torch::Device device = torch::kCPU;
  try {
    device = torch::Device(name);
  } catch (const std::exception&) {
    throw std::invalid_argument("device '" + name + "': expected cpu, cuda or cuda:N");
  }
  checkDeviceAvailable(device);
  return device;
}

void checkDeviceAvailable(const torch::Device& device) {
  if (device.is_cpu()) return;
  if (!device.is_cuda())
    throw std::invalid_argument("device '" + device.str() + "': only cpu and cuda are supported");
  if (!torch::cuda::is_available())
    throw std::invalid_argument("device '" + device.str() +
                                "': no CUDA device is available to this LibTorch build (a CPU-only "
                                "LibTorch, or no GPU or driver visible)");
  const int64_t count = int64_t(torch::cuda::device_count());
  if (device.has_index() && device.index() >= count)
    throw std::invalid_argument("device '" + device.str() + "': only " + std::to_string(count) +
                                " CUDA device(s) present");
}

std::optional<double> freeDeviceMemory(const torch::Device& device) {
  checkDeviceAvailable(device);
  if (!device.is_cuda())
    throw std::invalid_argument("device '" + device.str() + "': free memory is asked of CUDA only");
#if DN_WITH_CUDA
  const c10::cuda::CUDAGuard guard(device);
  std::size_t free = 0, total = 0;
  if (cudaMemGetInfo(&free, &total) != cudaSuccess)
    throw std::runtime_error("device '" + device.str() + "': cudaMemGetInfo failed");
  // The caching allocator answers only once a first allocation has set it up
  // ("Invalid device argument" otherwise).
  (void)torch::empty({1}, torch::TensorOptions().device(device));
  const auto stats =
      c10::cuda::CUDACachingAllocator::getDeviceStats(guard.current_device().index());
  constexpr std::size_t kAggregate = 0;  // StatType::AGGREGATE: all pools together
  const int64_t cachedUnused =
      stats.reserved_bytes[kAggregate].current - stats.allocated_bytes[kAggregate].current;
  return double(free) + double(std::max<int64_t>(0, cachedUnused));
#else
  return std::nullopt;
#endif
}

bool cpuComputesBFloat16() {
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
  __builtin_cpu_init();
  return __builtin_cpu_supports("amx-bf16") || __builtin_cpu_supports("avx512bf16");
#else
  return false;
#endif
}

}  // namespace dn
