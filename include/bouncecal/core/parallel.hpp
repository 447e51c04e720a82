// bouncecal/core/parallel.hpp — independent tasks on a few threads.
//
// The stages split their work into independent tasks, each writing only its own results (a slot
// of a vector), so what they compute does not depend on how many threads ran them or in which
// order. A stage says how many threads it may use (an Options struct's `threads`), never which:
// the threads are those of one executor of the process, a blocking pool in the style of Ceres'
// ThreadPool (its threads sleep on a condition variable between tasks; none spins). The caller
// of ParallelFor is one of the threads, so a call never waits for a busy executor: with no
// helper free it runs every task itself.
//
//   std::vector<double> out(n);
//   ParallelFor(ResolveThreads(options.threads), n, [&](std::size_t i) { out[i] = f(i); });
//
// Common mistakes: a task that writes shared state without its own slot (the result then
// depends on the scheduling); a count of threads read from the machine inside a stage (take
// the Options' `threads`, ResolveThreads turns 0 into the machine's).
#pragma once

#include <cstddef>
#include <functional>
#include <future>
#include <memory>
#include <type_traits>
#include <utility>

namespace bouncecal {

// Most threads an automatic count (0) resolves to: the stages split into a handful of
// independent parts, and more threads than that only add start-up cost.
constexpr int kMaxAutoThreads = 8;

// `requested` >= 1 as it is; 0: std::thread::hardware_concurrency() (1 when unknown), at most
// kMaxAutoThreads.
int ResolveThreads(int requested);

// Runs task(i) for every i in [0, n) on up to `threads` threads (the calling one included) and
// returns when all have finished. Tasks are taken in index order. A call made from inside a
// task (nested) works the same way; while the caller waits for the last tasks others run, it
// helps with other calls' tasks. If tasks throw, the exception of the lowest such i is
// rethrown once every task has run.
void ParallelFor(int threads, std::size_t n, const std::function<void(std::size_t)>& task);

// ParallelFor over [0, n) cut into consecutive groups of `group` indices (the last one shorter):
// task(begin, end) runs once per group, for per-index work too small to be a task of its own.
void ParallelForGroups(int threads, std::size_t n, std::size_t group,
                       const std::function<void(std::size_t, std::size_t)>& task);

// Starts job() on one of the executor's threads and returns at once; the future holds its
// result (or exception). Jobs start in the order given; the executor keeps at least `threads`
// threads for them, so that that many run at once. For a scheduler that overlaps its jobs with
// its own work (the blocks of a long recording with the reading of the next); a job must not
// wait for a job started after it.
void StartJob(int threads, std::function<void()> job);
template <typename F>
auto Async(int threads, F job) -> std::future<std::invoke_result_t<F&>> {
  using R = std::invoke_result_t<F&>;
  auto task = std::make_shared<std::packaged_task<R()>>(std::move(job));
  std::future<R> result = task->get_future();
  StartJob(threads, [task] { (*task)(); });
  return result;
}

}  // namespace bouncecal
