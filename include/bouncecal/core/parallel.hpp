// bouncecal/core/parallel.hpp — a fixed set of independent tasks on a few threads.
//
// Deterministic by construction: task i writes only its own results (a slot of a vector), so
// what the tasks compute does not depend on how many threads ran them or in which order.
//
//   std::vector<double> out(n);
//   ParallelFor(ResolveThreads(options.threads), n, [&](std::size_t i) { out[i] = f(i); });
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace bouncecal {

// Most threads an automatic count (0) resolves to: the stages split into a handful of
// independent parts, and more threads than that only add start-up cost.
constexpr int kMaxAutoThreads = 8;

// `requested` >= 1 as it is; 0: std::thread::hardware_concurrency() (1 when unknown), at most
// kMaxAutoThreads.
int ResolveThreads(int requested);

// The threads a stage may use when it starts: ResolveThreads(requested), and at most
// available() (at least 1) when that is set. A caller that runs several such stages at once
// gives each, through it, the cores the others leave idle; what the stages compute does not
// depend on the count.
int StageThreads(int requested, const std::function<int()>& available);

// Threads kept running for a series of ParallelFor calls (the stages of one detection). Without
// one, each call starts its threads and joins them: ~50 us per call back to back, and on a
// virtual machine whose idle cores sleep (this project's 2-core one) the new thread often starts
// 0.1-1 ms late, sometimes after the work is done (measured: a 1-minute recording's threshold
// stage, 3.4 ms on two threads when its second thread started at once, 5.5 ms when it never
// did). A pool's workers wait for the next call spinning for kSpinMicroseconds, then sleeping
// until it comes; the calling thread is one of the threads. One call at a time: a call made while
// another runs (from a task, or from another thread) gets false from TryRun and starts threads
// of its own, as without a pool. The results do not depend on it.
class WorkerPool {
 public:
  // How long an idle worker spins before it sleeps: stages follow each other within about this.
  static constexpr int kSpinMicroseconds = 2000;

  explicit WorkerPool(int threads);  // threads - 1 workers (the caller is the other one)
  ~WorkerPool();
  WorkerPool(const WorkerPool&) = delete;
  WorkerPool& operator=(const WorkerPool&) = delete;

  int threads() const { return static_cast<int>(workers_.size()) + 1; }

  // Runs body() on min(participants, threads()) threads, this one included, and returns true
  // when every one has returned; false, having run nothing, when another call is running.
  // body must not throw.
  bool TryRun(int participants, const std::function<void()>& body);

 private:
  void Loop(int index);

  std::mutex mutex_;
  std::condition_variable wake_;
  std::atomic<std::uint64_t> generation_{0};  // one more per call (and at the end)
  std::atomic<int> pending_{0};               // workers yet to answer the current call
  std::atomic<bool> busy_{false};             // a call is running
  std::atomic<bool> stop_{false};
  int sleeping_ = 0;      // under mutex_
  int participants_ = 0;  // the current call's, set before its generation
  const std::function<void()>* body_ = nullptr;
  std::vector<std::thread> workers_;
};

// Runs task(i) for every i in [0, n) on up to `threads` threads (the calling one included) and
// returns when all have finished: on `pool`'s threads when one is given and free, else on
// threads started for the call. If tasks throw, the exception of the lowest such i is rethrown.
void ParallelFor(int threads, std::size_t n, const std::function<void(std::size_t)>& task,
                 WorkerPool* pool = nullptr);

// ParallelFor over [0, n) cut into consecutive groups of `group` indices (the last one shorter):
// task(begin, end) runs once per group, for per-index work too small to be a task of its own.
void ParallelForGroups(int threads, std::size_t n, std::size_t group,
                       const std::function<void(std::size_t, std::size_t)>& task,
                       WorkerPool* pool = nullptr);

}  // namespace bouncecal
