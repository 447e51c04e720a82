// core/parallel.hpp: every task runs exactly once whatever the thread count (nested, concurrent
// and back-to-back calls, jobs), the count resolves as documented, and a task's exception
// reaches the caller (the lowest index's).
#include "bouncecal/core/parallel.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <functional>
#include <future>
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
  for (const int threads : {1, 2, 4, 3, 3}) {  // and the executor serves the next call
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

// The executor's threads serve call after call (none started per call): every task once, on at
// most `threads` distinct threads, the caller among them when it took a task.
TEST(ParallelFor, CallAfterCallEveryTaskRunsOnceOnAFewThreads) {
  std::vector<pid_t> seen;  // the threads of every call (kernel ids: not reused soon)
  for (int call = 0; call < 300; ++call) {
    if (call % 100 == 99) std::this_thread::sleep_for(std::chrono::milliseconds(5));  // asleep
    const int threads = 1 + call % 3;
    const std::size_t n = static_cast<std::size_t>(call % 37);
    std::vector<std::atomic<int>> runs(n);
    std::vector<pid_t> who(n);
    ParallelFor(threads, n, [&](std::size_t i) {
      ++runs[i];
      who[i] = gettid();
    });
    for (std::size_t i = 0; i < n; ++i)
      ASSERT_EQ(runs[i].load(), 1) << "call " << call << ", task " << i;
    std::sort(who.begin(), who.end());
    who.erase(std::unique(who.begin(), who.end()), who.end());
    EXPECT_LE(who.size(), static_cast<std::size_t>(threads)) << "call " << call;
    seen.insert(seen.end(), who.begin(), who.end());
  }
  std::sort(seen.begin(), seen.end());
  seen.erase(std::unique(seen.begin(), seen.end()), seen.end());
  // This thread and the executor's: at most the 8 the tests of this program ask for at once,
  // where a thread started per call would give hundreds.
  EXPECT_LE(seen.size(), 8u);
  EXPECT_NE(std::find(seen.begin(), seen.end(), gettid()), seen.end());
}

// Calls from inside tasks (nested) and from several threads at once: nothing waits for a busy
// executor (the caller runs what nobody takes), every task runs once.
TEST(ParallelFor, NestedAndConcurrentCallsRunEveryTaskOnce) {
  std::vector<std::atomic<int>> inner(8 * 16);
  ParallelFor(2, 8, [&](std::size_t i) {
    ParallelFor(3, 16, [&](std::size_t j) { ++inner[i * 16 + j]; });
  });
  for (std::size_t k = 0; k < inner.size(); ++k) EXPECT_EQ(inner[k].load(), 1) << k;
  std::vector<std::atomic<long>> sums(3);
  auto caller = [&](int c) {
    for (int call = 0; call < 200; ++call)
      ParallelFor(2, 50, [&](std::size_t i) { sums[c] += static_cast<long>(i); });
  };
  std::thread other(caller, 1), third(caller, 2);
  caller(0);
  other.join();
  third.join();
  for (int c = 0; c < 3; ++c) EXPECT_EQ(sums[c].load(), 200L * 1225L) << "caller " << c;
}

// A job started with Async runs on another thread while the caller goes on; its result and
// its exception come back through the future; jobs and ParallelFor calls inside them mix.
TEST(Async, JobsRunBesideTheCallerAndReturnTheirResults) {
  std::vector<std::future<long>> jobs;
  for (int j = 0; j < 6; ++j)
    jobs.push_back(Async(2, [j] {
      std::vector<long> part(100);
      ParallelFor(2, part.size(), [&](std::size_t i) { part[i] = j * static_cast<long>(i); });
      long sum = 0;
      for (long v : part) sum += v;
      return sum;
    }));
  for (int j = 0; j < 6; ++j) EXPECT_EQ(jobs[static_cast<std::size_t>(j)].get(), j * 4950L);
  // A job the caller waits for runs on another thread: the caller never runs jobs.
  const pid_t me = gettid();
  EXPECT_NE(Async(1, [] { return gettid(); }).get(), me);
  std::future<int> failing = Async(1, []() -> int { throw std::runtime_error("job failed"); });
  EXPECT_THROW(failing.get(), std::runtime_error);
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

}  // namespace
}  // namespace bouncecal
