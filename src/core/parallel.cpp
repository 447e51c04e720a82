// A fixed set of independent tasks on a few threads. See include/bouncecal/core/parallel.hpp.
#include "bouncecal/core/parallel.hpp"

#include <algorithm>
#include <atomic>
#include <exception>
#include <thread>
#include <vector>

namespace bouncecal {

int ResolveThreads(int requested) {
  if (requested >= 1) return requested;
  const unsigned n = std::thread::hardware_concurrency();
  return std::clamp(static_cast<int>(n), 1, kMaxAutoThreads);
}

int StageThreads(int requested, const std::function<int()>& available) {
  const int threads = ResolveThreads(requested);
  if (threads <= 1 || !available) return threads;
  return std::clamp(available(), 1, threads);
}

void ParallelFor(int threads, std::size_t n, const std::function<void(std::size_t)>& task) {
  const std::size_t workers =
      std::min<std::size_t>(n, static_cast<std::size_t>(std::max(1, threads)));
  if (workers <= 1) {
    for (std::size_t i = 0; i < n; ++i) task(i);
    return;
  }
  std::vector<std::exception_ptr> errors(n);
  std::atomic<std::size_t> next{0};
  auto work = [&]() {
    for (std::size_t i = next++; i < n; i = next++) {
      try {
        task(i);
      } catch (...) {
        errors[i] = std::current_exception();
      }
    }
  };
  std::vector<std::thread> pool;
  pool.reserve(workers - 1);
  for (std::size_t t = 1; t < workers; ++t) pool.emplace_back(work);
  work();
  for (std::thread& t : pool) t.join();
  for (const std::exception_ptr& e : errors)
    if (e) std::rethrow_exception(e);
}

void ParallelForGroups(int threads, std::size_t n, std::size_t group,
                       const std::function<void(std::size_t, std::size_t)>& task) {
  const std::size_t g = std::max<std::size_t>(1, group);
  ParallelFor(threads, (n + g - 1) / g,
              [&](std::size_t i) { task(i * g, std::min(n, (i + 1) * g)); });
}

}  // namespace bouncecal
