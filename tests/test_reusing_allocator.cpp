// The CPU allocator that keeps freed large blocks for reuse: a freed block
// comes back for its size or serves smaller ones, pieces merge again when
// freed, a larger request grows the cached range at the top (other cached
// memory going back first), the cache stays within its cap and under the
// high-water mark of the memory in use, small blocks are left to malloc,
// tensors made through it hold their values, and asked to, operator new
// takes its large blocks from the same cache.
#include <vector>

#include "doctest_torch.h"

#include "dn/nn/reusing_allocator.h"

using namespace dn;

namespace {

constexpr std::size_t kMiB = std::size_t(1) << 20;

torch::Tensor floats(std::size_t bytes) { return torch::empty({int64_t(bytes / sizeof(float))}); }

const char* address(const torch::Tensor& t) { return static_cast<const char*>(t.data_ptr()); }

void emptyCache(std::size_t cap) {
  useReusingCpuAllocator(0);
  useReusingCpuAllocator(cap);
}

}  // namespace

TEST_CASE("a freed large block is reused, serves smaller ones and merges back whole") {
  emptyCache(64 * kMiB);
  const char* first = nullptr;
  {
    torch::Tensor t = floats(8 * kMiB);
    first = address(t);
  }
  const std::size_t block = reusingCpuAllocatorCachedBytes();
  CHECK(block >= 8 * kMiB);
  {
    torch::Tensor same = floats(8 * kMiB);
    CHECK(address(same) == first);
    CHECK(reusingCpuAllocatorCachedBytes() == 0);
  }
  {
    torch::Tensor a = floats(3 * kMiB), b = floats(3 * kMiB);  // both from the freed block
    CHECK(address(a) == first);
    CHECK(address(b) > first);
    CHECK(address(b) + 3 * kMiB <= first + block);
    CHECK(reusingCpuAllocatorCachedBytes() < block);
  }
  CHECK(reusingCpuAllocatorCachedBytes() == block);  // the pieces merged
  torch::Tensor whole = floats(8 * kMiB);
  CHECK(address(whole) == first);
}

TEST_CASE("the cache stays within its cap and under the high-water mark") {
  emptyCache(64 * kMiB);
  {  // 12 blocks of 8 MiB in use at once, then freed: at most the cap is kept
    std::vector<torch::Tensor> many;
    for (int i = 0; i < 12; ++i) many.push_back(floats(8 * kMiB));
  }
  CHECK(reusingCpuAllocatorCachedBytes() == 64 * kMiB);
  {
    torch::Tensor fits = floats(40 * kMiB);  // from the cache
    const std::size_t left = reusingCpuAllocatorCachedBytes();
    CHECK(left < 64 * kMiB - 40 * kMiB + 2 * kMiB);
    // Fresh memory past the 12 blocks' mark: the cache goes back first.
    torch::Tensor fresh = floats(100 * kMiB);
    CHECK(reusingCpuAllocatorCachedBytes() == 0);
  }
  CHECK(reusingCpuAllocatorCachedBytes() == 64 * kMiB);

  const std::size_t before = reusingCpuAllocatorCachedBytes();
  { torch::Tensor small = floats(kMiB / 2); }
  CHECK(reusingCpuAllocatorCachedBytes() == before);  // under 1 MiB: malloc's

  useReusingCpuAllocator(0);  // a lower cap frees what it holds
  CHECK(reusingCpuAllocatorCachedBytes() == 0);
}

TEST_CASE("a request larger than every cached range grows the one at the top") {
  emptyCache(64 * kMiB);
  const char* first = nullptr;
  {
    torch::Tensor t = floats(8 * kMiB);
    t.fill_(7.0f);
    first = address(t);
  }
  CHECK(reusingCpuAllocatorCachedBytes() >= 8 * kMiB);
  torch::Tensor grown = floats(20 * kMiB);  // the cached 8 MiB, then fresh memory above it
  CHECK(address(grown) == first);
  CHECK(reusingCpuAllocatorCachedBytes() == 0);
  // Kept in memory, not given back and zeroed again: the old values are there.
  CHECK(grown[0].item<float>() == 7.0f);
  CHECK(grown[int64_t(8 * kMiB / sizeof(float)) - 1].item<float>() == 7.0f);
}

TEST_CASE("growing the range at the top gives other cached memory back first") {
  emptyCache(std::size_t(4) << 30);
  // Requests that take exactly `mib` MiB of the arena with the block's header.
  auto block = [](std::size_t mib) { return floats(mib * kMiB - 64); };
  torch::Tensor low = block(256), kept = block(8), top = block(256);
  const char* topAddress = address(top);
  low = top = torch::Tensor();
  CHECK(reusingCpuAllocatorCachedBytes() == 512 * kMiB);
  // No cached range holds 384 MiB: the top one grows by 128 MiB, and as much
  // of the low one goes back, so that what is resident stays at the 520 MiB
  // the three blocks took; the low one's 256 MiB would otherwise stay too.
  torch::Tensor grown = block(384);
  CHECK(address(grown) == topAddress);
  CHECK(reusingCpuAllocatorCachedBytes() == 128 * kMiB);
}

TEST_CASE("tensors through the allocator compute as usual") {
  emptyCache(64 * kMiB);
  for (int round = 0; round < 3; ++round) {  // the later rounds reuse the blocks
    const torch::Tensor a = torch::arange(1 << 22, torch::kFloat);
    const torch::Tensor b = a * 2 + 1;
    CHECK(b[12345].item<float>() == 2 * 12345 + 1);
    CHECK(b.sum().item<double>() == doctest::Approx(double(1 << 22) * (1 << 22)).epsilon(1e-6));
  }
}

// Last in the file: from here on the test program's large blocks come from the cache.
TEST_CASE("asked to, operator new's large blocks share the cache with the tensors") {
  emptyCache(64 * kMiB);
  useReusingAllocatorForNew();
  const float* data = nullptr;
  {
    torch::Tensor t = floats(8 * kMiB);  // freed by a tensor...
    data = static_cast<const float*>(t.data_ptr());
  }
  {
    std::vector<float> image(4 * kMiB / sizeof(float), 1.0f);  // ...taken by a vector
    CHECK(image.data() == data);
    CHECK(reusingCpuAllocatorCachedBytes() < 8 * kMiB);
  }
  CHECK(reusingCpuAllocatorCachedBytes() >= 8 * kMiB);  // and given back to the cache
  const std::size_t before = reusingCpuAllocatorCachedBytes();
  { std::vector<float> small(kMiB / 8); }  // under 1 MiB: malloc's
  CHECK(reusingCpuAllocatorCachedBytes() == before);
  auto* bytes = new char[2 * kMiB];  // arrays too
  bytes[2 * kMiB - 1] = 1;
  CHECK(reusingCpuAllocatorCachedBytes() < before);
  delete[] bytes;
  CHECK(reusingCpuAllocatorCachedBytes() == before);
}
