// Independent tasks on a few threads: the process's executor. See
// include/bouncecal/core/parallel.hpp.
#include "bouncecal/core/parallel.hpp"

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <deque>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

namespace bouncecal {

int ResolveThreads(int requested) {
  if (requested >= 1) return requested;
  const unsigned n = std::thread::hardware_concurrency();
  return std::clamp(static_cast<int>(n), 1, kMaxAutoThreads);
}

namespace {

// A blocking pool (as Ceres' ThreadPool): a queue of closures and threads that sleep on a
// condition variable until one comes. It grows to the most threads asked for and keeps them
// until the process ends. A queued closure is a job (StartJob) or a share of a ParallelFor call
// (a loop that takes that call's next index until none is left); a ParallelFor caller that waits
// for its last tasks runs queued shares meanwhile, never jobs.
class Executor {
 public:
  static Executor& Instance() {
    static Executor executor;
    return executor;
  }

  ~Executor() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      stop_ = true;
    }
    wake_.notify_all();
    for (std::thread& t : threads_) t.join();
  }

  // Queues `count` copies of a closure (count shares, or one job), with at least `threads`
  // threads to run them.
  void Enqueue(std::function<void()> closure, std::size_t count, bool share, int threads) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      while (static_cast<int>(threads_.size()) < threads) threads_.emplace_back([this] { Work(); });
      for (std::size_t i = 0; i < count; ++i) queue_.push_back({closure, share});
    }
    wake_.notify_all();  // idle threads and waiting callers
  }

  // Runs queued shares until done() holds; sleeps while there are none.
  void WaitHelping(const std::function<bool()>& done) {
    std::unique_lock<std::mutex> lock(mutex_);
    for (;;) {
      if (done()) return;
      const auto share =
          std::find_if(queue_.begin(), queue_.end(), [](const Queued& q) { return q.share; });
      if (share == queue_.end()) {
        ++waiting_;
        wake_.wait(lock);
        --waiting_;
        continue;
      }
      const std::function<void()> closure = std::move(share->closure);
      queue_.erase(share);
      lock.unlock();
      closure();
      lock.lock();
    }
  }

  // Wakes the callers in WaitHelping (a call's last task has finished).
  void NotifyDone() {
    std::lock_guard<std::mutex> lock(mutex_);
    if (waiting_ > 0) wake_.notify_all();
  }

 private:
  struct Queued {
    std::function<void()> closure;
    bool share = false;
  };

  Executor() = default;

  void Work() {
    std::unique_lock<std::mutex> lock(mutex_);
    for (;;) {
      wake_.wait(lock, [this] { return stop_ || !queue_.empty(); });
      if (stop_) return;
      const std::function<void()> closure = std::move(queue_.front().closure);
      queue_.pop_front();
      lock.unlock();
      closure();
      lock.lock();
    }
  }

  std::mutex mutex_;
  std::condition_variable wake_;  // a closure queued, a call done, or the end
  std::deque<Queued> queue_;
  std::vector<std::thread> threads_;
  int waiting_ = 0;  // callers asleep in WaitHelping
  bool stop_ = false;
};

// One ParallelFor call, shared with the shares queued for it (a share may start after the call
// has returned: it then finds no index left and touches nothing else).
struct Call {
  std::size_t n = 0;
  const std::function<void(std::size_t)>* task = nullptr;
  std::atomic<std::size_t> next{0};
  std::atomic<std::size_t> finished{0};
  std::vector<std::exception_ptr> errors;

  void RunShare() {
    for (std::size_t i = next++; i < n; i = next++) {
      try {
        (*task)(i);
      } catch (...) {
        errors[i] = std::current_exception();
      }
      if (finished.fetch_add(1) + 1 == n) Executor::Instance().NotifyDone();
    }
  }
};

}  // namespace

void ParallelFor(int threads, std::size_t n, const std::function<void(std::size_t)>& task) {
  const std::size_t workers =
      std::min<std::size_t>(n, static_cast<std::size_t>(std::max(1, threads)));
  if (workers <= 1) {
    for (std::size_t i = 0; i < n; ++i) task(i);
    return;
  }
  auto call = std::make_shared<Call>();
  call->n = n;
  call->task = &task;
  call->errors.resize(n);
  Executor& executor = Executor::Instance();
  executor.Enqueue([call] { call->RunShare(); }, workers - 1, true, static_cast<int>(workers) - 1);
  call->RunShare();
  executor.WaitHelping([&] { return call->finished.load() == n; });
  // The exceptions are released here, not by whichever thread drops the call last.
  std::exception_ptr first;
  for (std::exception_ptr& e : call->errors)
    if (e && !first) first = e;
  call->errors.clear();
  if (first) std::rethrow_exception(first);
}

void ParallelForGroups(int threads, std::size_t n, std::size_t group,
                       const std::function<void(std::size_t, std::size_t)>& task) {
  const std::size_t g = std::max<std::size_t>(1, group);
  ParallelFor(threads, (n + g - 1) / g,
              [&](std::size_t i) { task(i * g, std::min(n, (i + 1) * g)); });
}

void StartJob(int threads, std::function<void()> job) {
  Executor::Instance().Enqueue(std::move(job), 1, false, std::max(1, threads));
}

}  // namespace bouncecal
