#include "dn/temporal/parallel.h"

#include <algorithm>
#include <atomic>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

namespace dn::temporal {

void forEach(std::size_t count, int threads, const std::function<void(std::size_t)>& task) {
  std::atomic<std::size_t> next{0};
  std::exception_ptr failure;
  std::mutex failureMutex;
  auto worker = [&] {
    try {
      for (std::size_t i = next++; i < count; i = next++) task(i);
    } catch (...) {
      next = count;  // the others stop after their current task
      std::lock_guard<std::mutex> lock(failureMutex);
      if (!failure) failure = std::current_exception();
    }
  };
  std::vector<std::thread> pool;
  for (int t = 1; t < std::min<int>(threads, static_cast<int>(count)); ++t)
    pool.emplace_back(worker);
  worker();
  for (auto& t : pool) t.join();
  if (failure) std::rethrow_exception(failure);
}

void forBands(std::size_t count, int threads,
              const std::function<void(std::size_t, std::size_t)>& range) {
  const std::size_t bands = std::clamp<std::size_t>(threads, 1, std::max<std::size_t>(count, 1));
  forEach(bands, threads,
          [&](std::size_t b) { range(b * count / bands, (b + 1) * count / bands); });
}

}  // namespace dn::temporal
