#include "dn/infer/device.h"

#include <stdexcept>

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

}  // namespace dn
