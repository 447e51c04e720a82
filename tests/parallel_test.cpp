// core/parallel.hpp: every task runs exactly once whatever the thread count, the count resolves
// as documented, and a task's exception reaches the caller (the lowest index's).
#include "bouncecal/core/parallel.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <stdexcept>
#include <string>
#include <vector>

namespace bouncecal {
namespace {

TEST(ParallelFor, EveryTaskRunsOnceForAnyThreadCount) {
  for (const int threads : {1, 2, 3, 8}) {
    for (const std::size_t n : {std::size_t{0}, std::size_t{1}, std::size_t{5}, std::size_t{97}}) {
      std::vector<std::atomic<int>> runs(n);
      ParallelFor(threads, n, [&](std::size_t i) { ++runs[i]; });
      for (std::size_t i = 0; i < n; ++i)
        EXPECT_EQ(runs[i].load(), 1) << threads << " threads, n " << n << ", task " << i;
    }
  }
}

TEST(ParallelFor, TheLowestFailingTasksExceptionReachesTheCaller) {
  for (const int threads : {1, 2, 4}) {
    try {
      ParallelFor(threads, 40, [](std::size_t i) {
        if (i == 7 || i == 31) throw std::runtime_error("task " + std::to_string(i));
      });
      ADD_FAILURE() << threads << " threads: no exception";
    } catch (const std::runtime_error& e) {
      EXPECT_EQ(std::string(e.what()), "task 7") << threads << " threads";
    }
  }
}

TEST(ResolveThreads, ZeroIsTheHardwareConcurrencyCapped) {
  EXPECT_EQ(ResolveThreads(1), 1);
  EXPECT_EQ(ResolveThreads(3), 3);
  const int automatic = ResolveThreads(0);
  EXPECT_GE(automatic, 1);
  EXPECT_LE(automatic, kMaxAutoThreads);
}

}  // namespace
}  // namespace bouncecal
