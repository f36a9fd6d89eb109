#include "dn/nn/reusing_allocator.h"

#include <algorithm>
#include <cstdlib>
#include <cstring>
#include <map>
#include <mutex>
#include <new>
#include <utility>

#include <c10/core/Allocator.h>
#include <c10/core/impl/alloc_cpu.h>

#include <sys/mman.h>

namespace dn {
namespace {

constexpr std::size_t kMinCachedBlock = std::size_t(1) << 20;
constexpr std::size_t kMaxWaste = 4;  // a block serves requests up to a quarter smaller
// The block's size sits in front of its data, so that a raw pointer can be
// freed (Allocator::raw_deleter) and the data stays 64-byte aligned.
constexpr std::size_t kHeader = 64;

// Large blocks in transparent huge pages where the kernel grants them: a
// 1080p network's activations otherwise fault in 4 KiB at a time, which was a
// fifth of -q fast's CPU time, most of it in the kernel.
constexpr std::size_t kHugePage = std::size_t(2) << 20;

void* allocHuge(std::size_t bytes) {
  const std::size_t rounded = (bytes + kHugePage - 1) / kHugePage * kHugePage;
  void* block = std::aligned_alloc(kHugePage, rounded);
  if (!block) throw std::bad_alloc();
#ifdef MADV_HUGEPAGE
  madvise(block, rounded, MADV_HUGEPAGE);  // advice only: ignored where unsupported
#endif
  return block;
}

class ReusingCpuAllocator final : public c10::Allocator {
 public:
  // LibTorch 1.13 declares allocate const; 2.3 and later declare it non-const
  // and add copy_data. Both forms are here, so that either LibTorch finds its
  // own (the other is a plain member).
  c10::DataPtr allocate(std::size_t bytes) const {
    void* data = take(bytes);
    return {data, data, &release, c10::Device(c10::DeviceType::CPU)};
  }
  c10::DataPtr allocate(std::size_t bytes) { return std::as_const(*this).allocate(bytes); }
  void copy_data(void* dest, const void* src, std::size_t count) const {
    std::memcpy(dest, src, count);
  }
  c10::DeleterFnPtr raw_deleter() const override { return &release; }

  void setCap(std::size_t bytes) {
    std::lock_guard<std::mutex> lock(mutex_);
    cap_ = bytes;
    trim();
  }
  std::size_t cached() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return cached_;
  }

  static ReusingCpuAllocator& instance() {
    static auto* allocator = new ReusingCpuAllocator;  // never destroyed: tensors may outlive main
    return *allocator;
  }

 private:
  void* take(std::size_t bytes) const {
    if (bytes >= kMinCachedBlock) {
      std::lock_guard<std::mutex> lock(mutex_);
      // The smallest cached block that holds `bytes` and is at most a quarter
      // larger: a network's activations come in many sizes, and a fresh block
      // costs the kernel's zeroing of every page (1691 huge pages zeroed by a
      // 1080p -q fast run with exact sizes only, 1481 with this).
      auto it = free_.lower_bound(bytes);
      if (it != free_.end() && it->first <= bytes + bytes / kMaxWaste) {
        const std::size_t capacity = it->first;
        char* block = it->second;
        free_.erase(it);
        cached_ -= capacity;
        live_ += capacity;
        return block + kHeader;
      }
      live_ += bytes;
      // A new block: cached ones go first where live and cached blocks would
      // pass their high-water mark, so that the peak is the one without a cache.
      while (live_ + cached_ > highWater_ && !free_.empty()) evict();
      highWater_ = std::max(highWater_, live_ + cached_);
    }
    auto* block = static_cast<char*>(bytes >= kHugePage ? allocHuge(bytes + kHeader)
                                                        : c10::alloc_cpu(bytes + kHeader));
    *reinterpret_cast<std::size_t*>(block) = bytes;
    return block + kHeader;
  }

  static void release(void* data) {
    if (!data) return;
    char* block = static_cast<char*>(data) - kHeader;
    const std::size_t bytes = *reinterpret_cast<std::size_t*>(block);
    ReusingCpuAllocator& self = instance();
    if (bytes >= kMinCachedBlock) {
      std::lock_guard<std::mutex> lock(self.mutex_);
      self.live_ -= bytes;
      if (self.cached_ + bytes <= self.cap_) {
        self.free_.emplace(bytes, block);
        self.cached_ += bytes;
        return;
      }
    }
    c10::free_cpu(block);
  }

  // Frees the largest cached block.
  void evict() const {
    auto last = std::prev(free_.end());
    cached_ -= last->first;
    c10::free_cpu(last->second);
    free_.erase(last);
  }
  // Frees cached blocks, largest first, until the cache fits the cap.
  void trim() {
    while (cached_ > cap_ && !free_.empty()) evict();
  }

  mutable std::mutex mutex_;
  mutable std::multimap<std::size_t, char*> free_;  // by size
  mutable std::size_t cached_ = 0;
  mutable std::size_t live_ = 0;       // bytes of large blocks in use
  mutable std::size_t highWater_ = 0;  // the most of live_ + cached_ so far
  std::size_t cap_ = 0;
};

}  // namespace

void useReusingCpuAllocator(std::size_t maxCachedBytes) {
  ReusingCpuAllocator& allocator = ReusingCpuAllocator::instance();
  allocator.setCap(maxCachedBytes);
  c10::SetAllocator(c10::DeviceType::CPU, &allocator, /*priority=*/1);
}

std::size_t reusingCpuAllocatorCachedBytes() { return ReusingCpuAllocator::instance().cached(); }

}  // namespace dn
