// LibTorch's CPU allocator with a cache of freed large blocks. A network's
// activations are hundreds of megabytes; glibc hands blocks that large to the
// kernel (mmap) and back on every free, and the kernel zeroes every page again
// on first touch: 12 s of system time of 60 s CPU on a 1080p frame of the
// default, against 1.8 s for OIDN (docs/dndenoise.md#speed-and-memory). Here
// large blocks are carved from one reserved range of addresses, freed ones
// merge with their free neighbours, and any later request that fits takes
// them: memory zeroed once is zeroed once.
#pragma once

#include <cstddef>

namespace dn {

// Installs the allocator for every later CPU tensor (process-wide; tensors
// made before keep their own deleter). At most `maxCachedBytes` of freed
// memory is kept; past that the highest goes back to the system. A request
// that no cached range holds grows the cached range at the top of the arena,
// where there is one, so that only the growth is fresh. Either way, where the
// fresh memory would take the large blocks in use and cached past their
// high-water mark, other cached memory goes back first: what is resident
// stays within the most the blocks in use ever needed. Blocks under 1 MiB are
// left to malloc.
// Calling it again changes the cap.
void useReusingCpuAllocator(std::size_t maxCachedBytes);

// Bytes of freed blocks held for reuse now.
std::size_t reusingCpuAllocatorCachedBytes();

// Also serves the program's large blocks from operator new (images, weights)
// from the same memory, within the same cap: what the networks leave free
// between runs then holds, say, a sequence's temporal filter's images, where
// malloc would take fresh memory on top and give it back on every free.
void useReusingAllocatorForNew();

}  // namespace dn
