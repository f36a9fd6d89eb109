#include "dn/nn/reusing_allocator.h"

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <iterator>
#include <map>
#include <mutex>
#include <new>
#include <optional>
#include <set>
#include <utility>

#include <c10/core/Allocator.h>
#include <c10/core/impl/alloc_cpu.h>

#include <sys/mman.h>
#include <sys/resource.h>

namespace dn {
namespace {

constexpr std::size_t kMinCachedBlock = std::size_t(1) << 20;
// The block's length sits in front of its data, so that a raw pointer can be
// freed (Allocator::raw_deleter) and the data stays 64-byte aligned.
constexpr std::size_t kHeader = 64;
// Tensors' blocks are whole 2 MiB granules, so that the few sizes a network
// asks for fit each other's free ranges. The arena is not advised into
// transparent huge pages: on the development machines a fresh huge page cost
// more than the small pages it replaces, and a 1080p still took 1.46x the
// time with them (docs/RESULTS.md, "Transparent huge pages").
constexpr std::size_t kLargeGranule = std::size_t(2) << 20;
// Operator new's blocks are whole 64 KiB: they hold images, many of them for
// long (a sequence's window), and whole 2 MiB granules would add up to 2 MiB
// to each (a 1080p frame's 4.2 MiB depth took 6).
constexpr std::size_t kNewGranule = std::size_t(64) << 10;
// Addresses reserved for large blocks; only what is touched takes memory.
// Under a limit on the address space (ulimit -v, as some farms set) half of
// it at most, so that the rest of the process keeps room.
std::size_t arenaBytes() {
  std::size_t bytes = std::size_t(256) << 30;
  rlimit limit{};
  if (getrlimit(RLIMIT_AS, &limit) == 0 && limit.rlim_cur != RLIM_INFINITY)
    bytes = std::min<std::size_t>(bytes, limit.rlim_cur / 2 / kLargeGranule * kLargeGranule);
  return bytes;
}

std::size_t roundUp(std::size_t n, std::size_t to) { return (n + to - 1) / to * to; }

void* allocLarge(std::size_t bytes) {
  void* block = std::aligned_alloc(kLargeGranule, roundUp(bytes, kLargeGranule));
  if (!block) throw std::bad_alloc();
  return block;
}

// Large blocks are carved from one reserved range of addresses, the best fit
// among the free ranges, and a freed block merges with its free neighbours.
// Memory the kernel has zeroed once thus serves later requests of any size: a
// network's activations come in many sizes, and with blocks reused only for
// their own size a 1080p -q fast run had 3.2 GB of pages zeroed for a 1.4 GB
// peak. Free ranges still in memory are "cached"; past the cap, or where a
// request for fresh memory would take the memory in use and cached past its
// high-water mark, the highest go back to the kernel (MADV_DONTNEED) and
// become "idle". A request that no cached range holds first grows the cached
// range at the top, if there is one: with the decoder's phases run one at a
// time (oidn_unet.cpp) the high-water mark is lower, and giving back and
// zeroing again otherwise doubled the fresh pages of a 4K frame. Where the
// range cannot be reserved, large blocks come from aligned_alloc and go back
// on free.
class ReusingCpuAllocator final : public c10::Allocator {
 public:
  // LibTorch 1.13 declares allocate const; 2.3 and later declare it non-const
  // and add copy_data. Both forms are here, so that either LibTorch finds its
  // own (the other is a plain member).
  c10::DataPtr allocate(std::size_t bytes) const {
    void* data = const_cast<ReusingCpuAllocator*>(this)->take(bytes);
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
    dropCachedPastCap();
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
  struct Range {
    std::size_t length;
    bool cached;  // in memory; else given back (idle)
  };
  using BySize = std::set<std::pair<std::size_t, std::size_t>>;  // (length, offset)

  ReusingCpuAllocator() : size_(arenaBytes()) {
    if (size_ == 0) return;
    void* reserved = mmap(nullptr, size_ + kLargeGranule, PROT_READ | PROT_WRITE,
                          MAP_PRIVATE | MAP_ANONYMOUS | MAP_NORESERVE, -1, 0);
    if (reserved == MAP_FAILED) return;
    base_ =
        reinterpret_cast<char*>(roundUp(reinterpret_cast<std::uintptr_t>(reserved), kLargeGranule));
  }

  bool inArena(const char* block) const { return base_ && block >= base_ && block < base_ + size_; }

  void* take(std::size_t bytes) {
    if (bytes >= kMinCachedBlock)
      if (void* data = takeFromArena(bytes, kLargeGranule)) return data;
    char* block = static_cast<char*>(bytes >= kLargeGranule ? allocLarge(bytes + kHeader)
                                                            : c10::alloc_cpu(bytes + kHeader));
    *reinterpret_cast<std::size_t*>(block) = bytes + kHeader;
    return block + kHeader;
  }

 public:
  // A block of at least `bytes` from the arena, in whole `granule`s (a
  // tensor's, or operator new's); null where there is none (no arena, or full).
  void* takeFromArena(std::size_t bytes, std::size_t granule) {
    if (!base_) return nullptr;
    std::lock_guard<std::mutex> lock(mutex_);
    char* block = carveArena(roundUp(bytes + kHeader, granule));
    return block ? block + kHeader : nullptr;
  }
  bool owns(const void* data) const { return inArena(static_cast<const char*>(data) - kHeader); }
  static void release(void* data) {
    if (!data) return;
    char* block = static_cast<char*>(data) - kHeader;
    ReusingCpuAllocator& self = instance();
    if (!self.inArena(block)) return c10::free_cpu(block);
    std::lock_guard<std::mutex> lock(self.mutex_);
    const std::size_t length = *reinterpret_cast<std::size_t*>(block);
    self.live_ -= length;
    self.addFree(std::size_t(block - self.base_), {length, true});
    self.dropCachedPastCap();
  }

 private:
  // A block of `length` (whole granules) from the arena, or null when it is full.
  char* carveArena(std::size_t length) {
    std::optional<std::size_t> offset = takeBestFit(cachedBySize_, length);
    if (!offset) offset = extendTopRange(length);
    if (!offset) {
      // Fresh memory: the cache makes room first (the peak stays the one without it).
      while (live_ + cached_ + length > highWater_ && cached_ > 0)
        dropCached(live_ + cached_ + length - highWater_);
      offset = takeBestFit(idleBySize_, length);
    }
    if (!offset) {
      if (top_ + length > size_) return nullptr;
      offset = top_;
      top_ += length;
    }
    live_ += length;
    highWater_ = std::max(highWater_, live_ + cached_);
    char* block = base_ + *offset;
    *reinterpret_cast<std::size_t*>(block) = length;
    return block;
  }

  // The cached range that ends at the top, grown by fresh memory above it to
  // `length`: only the growth is zeroed, where a fresh block would be whole.
  // The other cached ranges make room for the growth first, as for any fresh
  // memory: a sequence's window, freed and taken in other sizes than the
  // networks' activations, otherwise kept 0.7 GB of cache resident and unused
  // at a 1080p shot's peak.
  std::optional<std::size_t> extendTopRange(std::size_t length) {
    if (free_.empty()) return std::nullopt;
    const auto [start, range] = *free_.rbegin();
    if (!range.cached || start + range.length != top_ || start + length > size_)
      return std::nullopt;
    const std::size_t growth = length - range.length;
    while (live_ + cached_ + growth > highWater_ && cached_ > range.length)
      dropCached(live_ + cached_ + growth - highWater_, start);
    removeFree(start);
    top_ = start + length;
    return start;
  }

  // Takes `length` from the start of the smallest range in `bySize` that holds it.
  std::optional<std::size_t> takeBestFit(BySize& bySize, std::size_t length) {
    auto it = bySize.lower_bound({length, 0});
    if (it == bySize.end()) return std::nullopt;
    const std::size_t offset = it->second;
    const Range range = free_.at(offset);
    removeFree(offset);
    if (range.length > length) addFree(offset + length, {range.length - length, range.cached});
    return offset;
  }

  // Adds a free range, merged with free neighbours in the same state; an idle
  // range that reaches the top lowers it instead.
  void addFree(std::size_t offset, Range range) {
    auto next = free_.lower_bound(offset);
    if (next != free_.end() && next->first == offset + range.length &&
        next->second.cached == range.cached) {
      range.length += next->second.length;
      removeFree(next->first);
    }
    auto prev = free_.lower_bound(offset);
    if (prev != free_.begin()) {
      --prev;
      if (prev->first + prev->second.length == offset && prev->second.cached == range.cached) {
        offset = prev->first;
        range.length += prev->second.length;
        removeFree(offset);
      }
    }
    if (!range.cached && offset + range.length == top_) {
      top_ = offset;
      return;
    }
    free_.emplace(offset, range);
    (range.cached ? cachedBySize_ : idleBySize_).insert({range.length, offset});
    if (range.cached) cached_ += range.length;
  }

  void removeFree(std::size_t offset) {
    auto it = free_.find(offset);
    const Range range = it->second;
    (range.cached ? cachedBySize_ : idleBySize_).erase({range.length, offset});
    if (range.cached) cached_ -= range.length;
    free_.erase(it);
  }

  // Gives up to `bytes` (whole granules) of memory back to the kernel from
  // the end of the highest cached range starting below `below`, as a heap
  // trims its top: the cache left stays in long ranges low in the arena.
  void dropCached(std::size_t bytes, std::size_t below = SIZE_MAX) {
    auto highest = std::make_reverse_iterator(free_.lower_bound(below));
    while (!highest->second.cached) ++highest;
    const std::size_t offset = highest->first, length = highest->second.length;
    const std::size_t dropped = std::min(length, roundUp(bytes, kLargeGranule));
    const std::size_t kept = length - dropped;
    removeFree(offset);
    if (kept > 0) addFree(offset, {kept, true});
    madvise(base_ + offset + kept, dropped, MADV_DONTNEED);
    addFree(offset + kept, {dropped, false});
  }
  void dropCachedPastCap() {
    while (cached_ > cap_) dropCached(cached_ - cap_);
  }

  const std::size_t size_;             // of the reserved range
  char* base_ = nullptr;               // the reserved range, granule-aligned; null if none
  std::size_t top_ = 0;                // offsets from here on were never handed out, or given back
  std::map<std::size_t, Range> free_;  // by offset
  BySize cachedBySize_, idleBySize_;
  std::size_t cached_ = 0;     // bytes of cached ranges
  std::size_t live_ = 0;       // bytes of arena blocks in use
  std::size_t highWater_ = 0;  // the most of live_ + cached_ so far
  std::size_t cap_ = 0;
  mutable std::mutex mutex_;
};

}  // namespace

void useReusingCpuAllocator(std::size_t maxCachedBytes) {
  ReusingCpuAllocator& allocator = ReusingCpuAllocator::instance();
  allocator.setCap(maxCachedBytes);
  c10::SetAllocator(c10::DeviceType::CPU, &allocator, /*priority=*/1);
}

std::size_t reusingCpuAllocatorCachedBytes() { return ReusingCpuAllocator::instance().cached(); }

namespace {
std::atomic<bool> forNew{false};
}  // namespace

void useReusingAllocatorForNew() {
  ReusingCpuAllocator::instance();  // reserved before the first block is routed
  forNew = true;
}

}  // namespace dn

// Replacements of the global operator new and delete (the others forward to
// these): large blocks from the arena once useReusingAllocatorForNew is called,
// everything else from malloc, as the default ones do.
void* operator new(std::size_t bytes) {
  using dn::ReusingCpuAllocator;
  if (dn::forNew && bytes >= dn::kMinCachedBlock)
    if (void* block = ReusingCpuAllocator::instance().takeFromArena(bytes, dn::kNewGranule))
      return block;
  for (;;) {
    if (void* block = std::malloc(bytes ? bytes : 1)) return block;
    std::new_handler handler = std::get_new_handler();
    if (!handler) throw std::bad_alloc();
    handler();
  }
}

void operator delete(void* data) noexcept {
  using dn::ReusingCpuAllocator;
  if (data && dn::forNew && ReusingCpuAllocator::instance().owns(data))
    return ReusingCpuAllocator::release(data);
  std::free(data);
}

void operator delete(void* data, std::size_t) noexcept { operator delete(data); }
