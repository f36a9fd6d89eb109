// A minimal parallel loop over rows for the image kernels (plain std::thread).
#pragma once

#include <algorithm>
#include <thread>
#include <vector>

namespace dn {

// Number of worker threads the image kernels use; 0 means hardware concurrency.
inline int& kernelThreadCount() {
  static int threads = 0;
  return threads;
}

// Calls body(begin, end) on contiguous chunks of [0, count) from several threads.
template <class Body>
void parallelFor(int count, Body&& body) {
  int threads = kernelThreadCount() > 0 ? kernelThreadCount()
                                        : static_cast<int>(std::thread::hardware_concurrency());
  threads = std::max(1, std::min(threads, count / 16));  // small jobs stay on one thread
  if (threads <= 1) {
    body(0, count);
    return;
  }
  std::vector<std::thread> workers;
  int chunk = (count + threads - 1) / threads;
  for (int begin = 0; begin < count; begin += chunk)
    workers.emplace_back(
        [&body, begin, end = std::min(count, begin + chunk)] { body(begin, end); });
  for (auto& w : workers) w.join();
}

}  // namespace dn
