#include "core/thread_pool.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <stdexcept>
#include <vector>

namespace twinforge::core {
namespace {

TEST(ThreadPool, RunsEveryTaskExactlyOnce) {
  for (int threads : {1, 2, 3, 8}) {
    ThreadPool pool(threads);
    EXPECT_EQ(pool.size(), threads);
    for (int64_t n : {0, 1, 2, 7, 1000}) {
      std::vector<std::atomic<int>> counts(n);
      pool.ParallelFor(n, [&](int64_t i) { counts[i].fetch_add(1); });
      for (int64_t i = 0; i < n; ++i) ASSERT_EQ(counts[i].load(), 1) << threads << " " << i;
    }
  }
}

TEST(ThreadPool, RangesCoverEveryItemOnceInContiguousNonEmptyPieces) {
  for (int threads : {1, 2, 3, 8}) {
    ThreadPool pool(threads);
    for (int64_t n : {0, 1, 2, 7, 1000}) {
      std::vector<std::atomic<int>> counts(n);
      std::atomic<int> ranges{0};
      pool.ParallelRanges(n, [&](int range, int64_t begin, int64_t end) {
        EXPECT_LT(begin, end) << threads << " " << n;
        EXPECT_LT(range, pool.size());
        ranges.fetch_add(1);
        for (int64_t i = begin; i < end; ++i) counts[i].fetch_add(1);
      });
      EXPECT_EQ(ranges.load(), std::min<int64_t>(threads, n)) << threads << " " << n;
      for (int64_t i = 0; i < n; ++i) ASSERT_EQ(counts[i].load(), 1) << threads << " " << i;
    }
  }
}

TEST(ThreadPool, ManyConsecutiveLoopsDoNotLoseWork) {
  ThreadPool pool(2);
  std::atomic<int64_t> sum{0};
  for (int round = 0; round < 2000; ++round)
    pool.ParallelFor(4, [&](int64_t i) { sum.fetch_add(i + 1); });
  EXPECT_EQ(sum.load(), 2000 * 10);
}

TEST(ThreadPool, RethrowsTheTaskException) {
  ThreadPool pool(2);
  EXPECT_THROW(pool.ParallelFor(10,
                                [](int64_t i) {
                                  if (i == 7) throw std::runtime_error("boom");
                                }),
               std::runtime_error);
  // The pool still works afterwards.
  std::atomic<int> count{0};
  pool.ParallelFor(10, [&](int64_t) { count++; });
  EXPECT_EQ(count.load(), 10);
}

}  // namespace
}  // namespace twinforge::core
