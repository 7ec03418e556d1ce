#include "core/rng.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/error.h"

namespace twinforge::core {
namespace {

TEST(Rng, SameSeedAndStreamGiveTheSameNumbers) {
  Rng a(7, 3), b(7, 3), c(7, 4), d(8, 3);
  const double first = a.Uniform();
  EXPECT_EQ(first, b.Uniform());
  EXPECT_NE(first, c.Uniform());
  EXPECT_NE(first, d.Uniform());
}

TEST(Rng, DistributionsHaveTheirMoments) {
  Rng rng(1);
  const int n = 200000;
  double sum = 0, sum_sq = 0, usum = 0;
  int hits = 0;
  for (int i = 0; i < n; ++i) {
    const double x = rng.Normal(2.0, 3.0);
    sum += x;
    sum_sq += x * x;
    const double u = rng.Uniform(-1.0, 3.0);
    ASSERT_GE(u, -1.0);
    ASSERT_LT(u, 3.0);
    usum += u;
    const int64_t k = rng.Int(-2, 2);
    ASSERT_GE(k, -2);
    ASSERT_LE(k, 2);
    hits += k == 2;
  }
  const double mean = sum / n;
  EXPECT_NEAR(mean, 2.0, 0.05);
  EXPECT_NEAR(std::sqrt(sum_sq / n - mean * mean), 3.0, 0.05);
  EXPECT_NEAR(usum / n, 1.0, 0.02);
  EXPECT_NEAR(hits / double(n), 0.2, 0.01);
}

TEST(Rng, SaveAndLoadResumeExactly) {
  Rng rng(5);
  for (int i = 0; i < 10; ++i) rng.Uniform();
  const std::string state = rng.Save();
  const double next = rng.Normal();
  Rng restored(999);
  restored.Load(state);
  EXPECT_EQ(restored.Normal(), next);
  EXPECT_THROW(restored.Load("garbage"), Error);
}

TEST(Rng, ShuffleIsAPermutation) {
  Rng rng(2);
  std::vector<int> items{0, 1, 2, 3, 4, 5, 6, 7};
  rng.Shuffle(items);
  std::vector<int> sorted = items;
  std::sort(sorted.begin(), sorted.end());
  EXPECT_EQ(sorted, (std::vector<int>{0, 1, 2, 3, 4, 5, 6, 7}));
}

}  // namespace
}  // namespace twinforge::core
