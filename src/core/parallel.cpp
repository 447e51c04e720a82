// A fixed set of independent tasks on a few threads. See include/bouncecal/core/parallel.hpp.
#include "bouncecal/core/parallel.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <exception>
#include <thread>
#include <vector>

#if defined(__x86_64__) || defined(__i386__)
#include <immintrin.h>
#endif

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

namespace {

// A spinning thread's pause (x86: lets the other hyperthread of the core run, and saves power).
inline void SpinPause() {
#if defined(__x86_64__) || defined(__i386__)
  _mm_pause();
#endif
}

}  // namespace

WorkerPool::WorkerPool(int threads) {
  const int n = std::max(1, threads) - 1;
  workers_.reserve(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) workers_.emplace_back([this, i] { Loop(i); });
}

WorkerPool::~WorkerPool() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_.store(true);
    generation_.fetch_add(1, std::memory_order_release);
  }
  wake_.notify_all();
  for (std::thread& t : workers_) t.join();
}

void WorkerPool::Loop(int index) {
  std::uint64_t seen = 0;
  for (;;) {
    // The next call: spin for kSpinMicroseconds, then sleep until it comes.
    const auto until =
        std::chrono::steady_clock::now() + std::chrono::microseconds(kSpinMicroseconds);
    std::uint64_t now = generation_.load(std::memory_order_acquire);
    for (int spins = 1; now == seen; ++spins) {
      if (spins % 64 == 0 && std::chrono::steady_clock::now() > until) {
        std::unique_lock<std::mutex> lock(mutex_);
        ++sleeping_;
        wake_.wait(lock, [&] { return generation_.load(std::memory_order_acquire) != seen; });
        --sleeping_;
      } else {
        SpinPause();
      }
      now = generation_.load(std::memory_order_acquire);
    }
    seen = now;
    if (stop_.load()) return;
    // Every worker answers every call, taking part or not, so that the next call's fields are
    // not written while one still reads this call's.
    if (index < participants_ - 1) (*body_)();
    pending_.fetch_sub(1, std::memory_order_acq_rel);
  }
}

bool WorkerPool::TryRun(int participants, const std::function<void()>& body) {
  bool idle = false;
  if (!busy_.compare_exchange_strong(idle, true)) return false;
  const int n = std::clamp(participants, 1, threads());
  body_ = &body;
  participants_ = n;
  pending_.store(static_cast<int>(workers_.size()), std::memory_order_relaxed);
  bool wake = false;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    generation_.fetch_add(1, std::memory_order_release);  // publishes body_ and participants_
    wake = sleeping_ > 0;
  }
  if (wake) wake_.notify_all();
  body();
  // The workers' shares end about when this thread's does (the tasks are taken one by one); a
  // worker that was asleep answers once it wakes.
  for (int spins = 1; pending_.load(std::memory_order_acquire) != 0; ++spins) {
    if (spins % 1024 == 0)
      std::this_thread::yield();
    else
      SpinPause();
  }
  busy_.store(false, std::memory_order_release);
  return true;
}

void ParallelFor(int threads, std::size_t n, const std::function<void(std::size_t)>& task,
                 WorkerPool* pool) {
  const std::size_t workers =
      std::min<std::size_t>(n, static_cast<std::size_t>(std::max(1, threads)));
  if (workers <= 1) {
    for (std::size_t i = 0; i < n; ++i) task(i);
    return;
  }
  std::vector<std::exception_ptr> errors(n);
  std::atomic<std::size_t> next{0};
  const std::function<void()> work = [&]() {
    for (std::size_t i = next++; i < n; i = next++) {
      try {
        task(i);
      } catch (...) {
        errors[i] = std::current_exception();
      }
    }
  };
  if (pool == nullptr || !pool->TryRun(static_cast<int>(workers), work)) {
    std::vector<std::thread> started;
    started.reserve(workers - 1);
    for (std::size_t t = 1; t < workers; ++t) started.emplace_back(work);
    work();
    for (std::thread& t : started) t.join();
  }
  for (const std::exception_ptr& e : errors)
    if (e) std::rethrow_exception(e);
}

void ParallelForGroups(int threads, std::size_t n, std::size_t group,
                       const std::function<void(std::size_t, std::size_t)>& task,
                       WorkerPool* pool) {
  const std::size_t g = std::max<std::size_t>(1, group);
  ParallelFor(
      threads, (n + g - 1) / g, [&](std::size_t i) { task(i * g, std::min(n, (i + 1) * g)); },
      pool);
}

}  // namespace bouncecal
