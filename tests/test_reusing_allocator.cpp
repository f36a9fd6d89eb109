// The CPU allocator that keeps freed large blocks for reuse: the same block
// comes back for the same size or one up to a quarter smaller, the cache stays within its cap,
// small blocks are left to malloc, and tensors made through it hold their values.
#include "doctest_torch.h"

#include "dn/nn/reusing_allocator.h"

using namespace dn;

namespace {

constexpr std::size_t kMiB = std::size_t(1) << 20;

torch::Tensor floats(std::size_t bytes) { return torch::empty({int64_t(bytes / sizeof(float))}); }

}  // namespace

TEST_CASE("a freed large block is reused for the same size, within the cap") {
  useReusingCpuAllocator(64 * kMiB);
  void* first = nullptr;
  {
    torch::Tensor t = floats(8 * kMiB);
    first = t.data_ptr();
  }
  CHECK(reusingCpuAllocatorCachedBytes() == 8 * kMiB);
  {
    torch::Tensor same = floats(8 * kMiB);
    CHECK(same.data_ptr() == first);
    CHECK(reusingCpuAllocatorCachedBytes() == 0);
    torch::Tensor other = floats(4 * kMiB);  // another size: a new block
    CHECK(other.data_ptr() != first);
  }
  CHECK(reusingCpuAllocatorCachedBytes() == 12 * kMiB);

  {  // freed beyond the cap: back to the system
    std::vector<torch::Tensor> many;
    for (int i = 0; i < 12; ++i) many.push_back(floats(8 * kMiB));
  }

  // 12 blocks of 8 MiB were in use at once: a new 40 MiB block may not take
  // blocks in use and cached past those 96 MiB, so one cached block goes.
  REQUIRE(reusingCpuAllocatorCachedBytes() == 64 * kMiB);
  {
    torch::Tensor big = floats(40 * kMiB);
    CHECK(reusingCpuAllocatorCachedBytes() == 56 * kMiB);
  }
  CHECK(reusingCpuAllocatorCachedBytes() == 56 * kMiB);  // beyond the cap: not kept

  const std::size_t before = reusingCpuAllocatorCachedBytes();
  { torch::Tensor small = floats(kMiB / 2); }
  CHECK(reusingCpuAllocatorCachedBytes() == before);  // under 1 MiB: malloc's

  useReusingCpuAllocator(0);  // a lower cap frees what it holds
  CHECK(reusingCpuAllocatorCachedBytes() == 0);
}

TEST_CASE("a freed block serves a request up to a quarter smaller, and returns whole") {
  useReusingCpuAllocator(0);
  useReusingCpuAllocator(64 * kMiB);
  void* first = nullptr;
  {
    torch::Tensor t = floats(10 * kMiB);
    first = t.data_ptr();
  }
  {
    torch::Tensor smaller = floats(9 * kMiB);
    CHECK(smaller.data_ptr() == first);
    CHECK(reusingCpuAllocatorCachedBytes() == 0);
  }
  CHECK(reusingCpuAllocatorCachedBytes() == 10 * kMiB);  // back at its full size
  {
    torch::Tensor muchSmaller = floats(7 * kMiB);  // 10 > 1.25 x 7: a new block
    CHECK(muchSmaller.data_ptr() != first);
  }
  useReusingCpuAllocator(0);
}

TEST_CASE("tensors through the allocator compute as usual") {
  useReusingCpuAllocator(64 * kMiB);
  for (int round = 0; round < 3; ++round) {  // the later rounds reuse the blocks
    const torch::Tensor a = torch::arange(1 << 20, torch::kFloat);
    const torch::Tensor b = a * 2 + 1;
    CHECK(b[12345].item<float>() == 2 * 12345 + 1);
    CHECK(b.sum().item<double>() == doctest::Approx(double(1 << 20) * (1 << 20)).epsilon(1e-6));
  }
}
