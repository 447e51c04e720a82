// core/parallel.hpp: every task runs exactly once whatever the thread count, the count resolves
// as documented, and a task's exception reaches the caller (the lowest index's).
#include "bouncecal/core/parallel.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <functional>
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

TEST(ParallelForGroups, GroupsAreContiguousAndCoverEveryIndexOnce) {
  for (const int threads : {1, 2, 3}) {
    for (const std::size_t n : {std::size_t{0}, std::size_t{1}, std::size_t{64}, std::size_t{97}}) {
      std::vector<std::atomic<int>> runs(n);
      std::atomic<int> groups{0};
      ParallelForGroups(threads, n, 16, [&](std::size_t begin, std::size_t end) {
        EXPECT_EQ(begin % 16, 0u);
        EXPECT_EQ(end, std::min(n, begin + 16));
        ++groups;
        for (std::size_t i = begin; i < end; ++i) ++runs[i];
      });
      EXPECT_EQ(groups.load(), static_cast<int>((n + 15) / 16)) << threads << " threads, n " << n;
      for (std::size_t i = 0; i < n; ++i) EXPECT_EQ(runs[i].load(), 1) << "index " << i;
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

TEST(StageThreads, TheAvailableCountCapsTheRequestedOneAndNeverGoesBelowOne) {
  int asked = 0;
  auto available = [&asked](int n) {
    return std::function<int()>([&asked, n] {
      ++asked;
      return n;
    });
  };
  EXPECT_EQ(StageThreads(4, nullptr), 4);       // no cap
  EXPECT_EQ(StageThreads(4, available(2)), 2);  // capped
  EXPECT_EQ(StageThreads(4, available(9)), 4);  // never more than requested
  EXPECT_EQ(StageThreads(4, available(0)), 1);  // at least the calling thread
  EXPECT_EQ(StageThreads(4, available(-3)), 1);
  EXPECT_EQ(asked, 4);
  EXPECT_EQ(StageThreads(1, available(8)), 1);  // one thread: not asked
  EXPECT_EQ(asked, 4);
  EXPECT_EQ(StageThreads(0, available(1)), 1);
}

}  // namespace
}  // namespace bouncecal
