// core/parallel.hpp: every task runs exactly once whatever the thread count, the count resolves
// as documented, and a task's exception reaches the caller (the lowest index's).
#include "bouncecal/core/parallel.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <functional>
#include <stdexcept>
#include <string>
#include <thread>
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

// A pool's threads serve call after call: every task once, on the pool's threads (at most
// min(threads, pool size) distinct ones, the caller among them), whether the workers were
// spinning (calls back to back) or asleep (a pause longer than WorkerPool::kSpinMicroseconds).
TEST(WorkerPool, CallAfterCallEveryTaskRunsOnceOnThePoolsThreads) {
  for (const int pool_threads : {1, 2, 3}) {
    WorkerPool pool(pool_threads);
    ASSERT_EQ(pool.threads(), pool_threads);
    std::vector<pid_t> seen;  // the threads of every call (kernel ids: not reused soon)
    for (int call = 0; call < 300; ++call) {
      if (call % 100 == 99)
        std::this_thread::sleep_for(std::chrono::microseconds(3 * WorkerPool::kSpinMicroseconds));
      const int threads = 1 + call % 4;
      const std::size_t n = static_cast<std::size_t>(call % 37);
      std::vector<std::atomic<int>> runs(n);
      std::vector<pid_t> who(n);
      ParallelFor(
          threads, n,
          [&](std::size_t i) {
            ++runs[i];
            who[i] = gettid();
          },
          &pool);
      for (std::size_t i = 0; i < n; ++i)
        ASSERT_EQ(runs[i].load(), 1) << "call " << call << ", task " << i;
      std::sort(who.begin(), who.end());
      who.erase(std::unique(who.begin(), who.end()), who.end());
      EXPECT_LE(who.size(), static_cast<std::size_t>(std::min(threads, pool_threads)))
          << "call " << call;
      seen.insert(seen.end(), who.begin(), who.end());
    }
    std::sort(seen.begin(), seen.end());
    seen.erase(std::unique(seen.begin(), seen.end()), seen.end());
    EXPECT_LE(seen.size(), static_cast<std::size_t>(pool_threads));  // no thread started per call
    EXPECT_NE(std::find(seen.begin(), seen.end(), gettid()), seen.end());
  }
}

// A call made while the pool runs another (from one of its tasks, or from another thread) runs
// on threads of its own: nothing waits for the pool, every task runs once.
TEST(WorkerPool, CallsWhileItIsBusyRunOnTheirOwnThreads) {
  WorkerPool pool(2);
  std::vector<std::atomic<int>> inner(8 * 16);
  ParallelFor(
      2, 8,
      [&](std::size_t i) {
        ParallelFor(
            2, 16, [&](std::size_t j) { ++inner[i * 16 + j]; }, &pool);
      },
      &pool);
  for (std::size_t k = 0; k < inner.size(); ++k) EXPECT_EQ(inner[k].load(), 1) << k;
  // Two threads calling at once, many times.
  std::vector<std::atomic<long>> sums(2);
  auto caller = [&](int c) {
    for (int call = 0; call < 200; ++call)
      ParallelFor(
          2, 50, [&](std::size_t i) { sums[c] += static_cast<long>(i); }, &pool);
  };
  std::thread other(caller, 1);
  caller(0);
  other.join();
  EXPECT_EQ(sums[0].load(), 200L * 1225L);
  EXPECT_EQ(sums[1].load(), 200L * 1225L);
  // TryRun itself says so: busy while its body runs, on both threads.
  std::atomic<int> refused{0};
  EXPECT_TRUE(pool.TryRun(2, [&] {
    if (!pool.TryRun(2, [] {})) ++refused;
  }));
  EXPECT_EQ(refused.load(), 2);
}

TEST(WorkerPool, TheLowestFailingTasksExceptionReachesTheCaller) {
  WorkerPool pool(3);
  for (int round = 0; round < 3; ++round) {  // and the pool serves the next call
    try {
      ParallelFor(
          3, 40,
          [](std::size_t i) {
            if (i == 7 || i == 31) throw std::runtime_error("task " + std::to_string(i));
          },
          &pool);
      ADD_FAILURE() << "no exception";
    } catch (const std::runtime_error& e) {
      EXPECT_EQ(std::string(e.what()), "task 7");
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
