#include "real2sim/calibrate/losses.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <numeric>

namespace twinforge::real2sim {
namespace {

const auto kDouble = torch::TensorOptions().dtype(torch::kFloat64);

// The cheapest one-to-one assignment's mean distance, by trying every permutation.
double ExactAssignment(const torch::Tensor& a, const torch::Tensor& b) {
  const auto cost = torch::cdist(a, b);
  std::vector<int> order(a.size(0));
  std::iota(order.begin(), order.end(), 0);
  double best = 1e30;
  do {
    double total = 0;
    for (size_t i = 0; i < order.size(); ++i) total += cost[i][order[i]].item<double>();
    best = std::min(best, total / order.size());
  } while (std::next_permutation(order.begin(), order.end()));
  return best;
}

TEST(SinkhornEmd, MatchesTheExactAssignmentOnSmallSets) {
  torch::manual_seed(4);
  for (int trial = 0; trial < 3; ++trial) {
    const auto a = torch::rand({7, 3}, kDouble) * 0.2;
    const auto b = torch::rand({7, 3}, kDouble) * 0.2 + 0.03;
    const double exact = ExactAssignment(a, b);
    const double sinkhorn = SinkhornEmd(a, b, 0.0005, 2000).item<double>();
    EXPECT_NEAR(sinkhorn, exact, 0.02 * exact) << "trial " << trial;
    // Chamfer lets many points share a nearest one: never more than the assignment's cost twice.
    EXPECT_LE(ChamferDistance(a, b).item<double>(), 2 * exact + 1e-12);
  }
}

TEST(SinkhornEmd, GradientPullsOneCloudOntoTheOther) {
  torch::manual_seed(5);
  const auto target = torch::rand({64, 3}, kDouble) * 0.3;
  auto moving = (target + torch::tensor({0.05, -0.03, 0.02}, kDouble)).requires_grad_(true);
  torch::optim::Adam adam({moving}, torch::optim::AdamOptions(0.002));
  const double before = SinkhornEmd(moving, target).item<double>();
  for (int i = 0; i < 100; ++i) {
    const auto loss = SinkhornEmd(moving, target, 0.002, 100);
    adam.zero_grad();
    loss.backward();
    adam.step();
  }
  EXPECT_LT(SinkhornEmd(moving, target).item<double>(), 0.2 * before);
}

TEST(ImageLosses, ZeroAtTheTargetAndPositiveAway) {
  torch::manual_seed(6);
  const auto rgb = torch::rand({6, 8, 3}, kDouble);
  const auto mask = (torch::rand({6, 8}, kDouble) > 0.3).to(torch::kFloat64);
  const auto depth = 0.5 + torch::rand({6, 8}, kDouble) * 0.1;
  const auto full = torch::ones({6, 8}, kDouble);
  EXPECT_NEAR(RgbLoss(rgb, full, rgb, mask).item<double>(), 0, 1e-12);
  EXPECT_GT(RgbLoss(rgb + 0.1, full, rgb, mask).item<double>(), 0.09);
  EXPECT_NEAR(DepthLoss(depth, full, depth).item<double>(), 0, 1e-12);
  EXPECT_GT(DepthLoss(depth + 0.02, full, depth).item<double>(), 0);
  // Beyond the outlier distance a pixel costs a constant, the same as a pixel not covered.
  const double cap = DepthLoss(depth + 0.3, full, depth, 0.01, 0.05).item<double>();
  EXPECT_NEAR(cap, 0.01 * (0.05 - 0.005), 1e-12);
  EXPECT_NEAR(DepthLoss(depth, 0 * full, depth, 0.01, 0.05).item<double>(), cap, 1e-12);
  EXPECT_LT(DepthLoss(depth + 0.02, full, depth, 0.01, 0.05).item<double>(), cap);
  EXPECT_NEAR(SilhouetteLoss(mask, mask).item<double>(), 0, 1e-9);
  EXPECT_NEAR(SilhouetteLoss(1 - mask, mask).item<double>(), 1, 1e-12);
}

}  // namespace
}  // namespace twinforge::real2sim
