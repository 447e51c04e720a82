// bouncecal/core/parallel.hpp — a fixed set of independent tasks on a few threads.
//
// Deterministic by construction: task i writes only its own results (a slot of a vector), so
// what the tasks compute does not depend on how many threads ran them or in which order.
//
//   std::vector<double> out(n);
//   ParallelFor(ResolveThreads(options.threads), n, [&](std::size_t i) { out[i] = f(i); });
#pragma once

#include <cstddef>
#include <functional>

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

// Runs task(i) for every i in [0, n) on up to `threads` threads (the calling one included) and
// returns when all have finished. If tasks throw, the exception of the lowest such i is
// rethrown.
void ParallelFor(int threads, std::size_t n, const std::function<void(std::size_t)>& task);

// ParallelFor over [0, n) cut into consecutive groups of `group` indices (the last one shorter):
// task(begin, end) runs once per group, for per-index work too small to be a task of its own.
void ParallelForGroups(int threads, std::size_t n, std::size_t group,
                       const std::function<void(std::size_t, std::size_t)>& task);

}  // namespace bouncecal
