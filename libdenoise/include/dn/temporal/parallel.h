// The temporal filter's and the sequence's threads: tasks run on a few
// threads started for the call (the networks' own pool is idle meanwhile).
#pragma once

#include <cstddef>
#include <functional>

namespace dn::temporal {

// Runs task(0 .. count-1) on up to `threads` threads, the calling one among
// them; the first exception thrown is rethrown here, after every thread has
// stopped.
void forEach(std::size_t count, int threads, const std::function<void(std::size_t)>& task);

// Runs range(begin, end) over bands of [0, count) on up to `threads` threads.
void forBands(std::size_t count, int threads,
              const std::function<void(std::size_t, std::size_t)>& range);

}  // namespace dn::temporal
