// A fixed-size pool of worker threads for data-parallel loops.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <exception>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace twinforge::core {

class ThreadPool {
 public:
  // `threads` workers in total, counting the calling thread (so 1 means: run inline).
  explicit ThreadPool(int threads);
  ~ThreadPool();
  ThreadPool(const ThreadPool&) = delete;
  ThreadPool& operator=(const ThreadPool&) = delete;

  int size() const { return static_cast<int>(workers_.size()) + 1; }

  // Calls fn(i) exactly once for each i in [0, n), spread over the pool, and returns when all
  // are done. Threads take the next item from a shared counter; a call allocates nothing. The first
  // exception thrown by fn is rethrown here after the others finish. One caller at a time: a pool
  // serves one loop, not several concurrent ones.
  void ParallelFor(int64_t n, const std::function<void(int64_t)>& fn);

  // Splits items [0, count) into contiguous ranges, at most one per thread and none empty, and
  // calls fn(range, begin, end) for each, so that a range builds its costly state (an env) once.
  // Which range an item falls in depends on the pool's size: a result that must not depend on the
  // thread count has to depend on the item's index only.
  void ParallelRanges(int64_t count,
                      const std::function<void(int range, int64_t begin, int64_t end)>& fn);

 private:
  void WorkerLoop(int worker);
  void RunBlock(int block);

  std::vector<std::thread> workers_;
  std::mutex mutex_;
  std::condition_variable start_;
  std::condition_variable finished_;
  const std::function<void(int64_t)>* job_ = nullptr;
  int64_t job_size_ = 0;
  std::atomic<int64_t> next_{0};
  uint64_t generation_ = 0;
  int pending_ = 0;
  bool stopping_ = false;
  std::exception_ptr error_;
};

// The default worker count: the machine's hardware threads (at least 1).
int DefaultThreadCount();

}  // namespace twinforge::core
