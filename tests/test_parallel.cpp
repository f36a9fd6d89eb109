// The temporal filter's threads: every task runs once whatever the thread
// count, bands cover the range without overlap, and a task's exception
// reaches the caller once every thread has stopped.
#include <atomic>
#include <chrono>
#include <stdexcept>
#include <thread>
#include <vector>

#include <doctest/doctest.h>

#include "dn/temporal/parallel.h"

using namespace dn::temporal;

TEST_CASE("every task runs once, on any number of threads") {
  for (int threads : {1, 2, 3, 16}) {
    for (std::size_t count : {std::size_t(0), std::size_t(1), std::size_t(7), std::size_t(100)}) {
      CAPTURE(threads);
      CAPTURE(count);
      std::vector<std::atomic<int>> runs(count);
      forEach(count, threads, [&](std::size_t i) { ++runs[i]; });
      for (const auto& r : runs) CHECK(r == 1);
    }
  }
}

TEST_CASE("bands cover the range once, in order within each band") {
  for (int threads : {1, 2, 5}) {
    for (std::size_t count : {std::size_t(0), std::size_t(3), std::size_t(1153)}) {
      std::vector<std::atomic<int>> covered(count);
      forBands(count, threads, [&](std::size_t begin, std::size_t end) {
        CHECK(begin <= end);
        for (std::size_t i = begin; i < end; ++i) ++covered[i];
      });
      for (const auto& c : covered) CHECK(c == 1);
    }
  }
}

TEST_CASE("a task's exception reaches the caller, and the other threads stop taking tasks") {
  // Each task takes a millisecond, far longer than the exception takes to
  // reach the catch: an empty task would let the other thread run through
  // all of them while the first exception of the process unwinds.
  std::atomic<int> started{0};
  CHECK_THROWS_WITH_AS(forEach(1000, 2,
                               [&](std::size_t i) {
                                 ++started;
                                 if (i == 3) throw std::runtime_error("task 3 failed");
                                 std::this_thread::sleep_for(std::chrono::milliseconds(1));
                               }),
                       "task 3 failed", std::runtime_error);
  CHECK(started < 100);
}
