#include "samrl/pose_estimate.h"

#include <gtest/gtest.h>

#include "core/se3.h"
#include "sim/task.h"

namespace twinforge::samrl {
namespace {

// The square peg and the block with its square hole look the same every quarter turn; the
// spatula only once a turn. Of a fit's look-alike poses, the one nearest the twin's own is taken,
// or the one nearest where the object was believed.
TEST(PoseEstimate, LookAlikeTurnsOfSquareObjects) {
  auto peg = std::make_shared<const sim::Task>(sim::LoadTaskSpec("peg_insertion"));
  const ObjectPoseEstimator estimator(peg, {"peg", "hole_block"});
  EXPECT_EQ(estimator.symmetry(0), 4);
  EXPECT_EQ(estimator.symmetry(1), 4);
  for (int i = 0; i < 2; ++i)
    for (double turn : {0.0, 0.5, 1.0, 1.5}) {
      const double yaw = 0.2 + M_PI * turn;  // 0.2 rad from the twin's own, and quarter turns
      core::Pose fitted = estimator.nominal(i);
      fitted.translation.x() += 0.03;
      fitted.rotation = core::Yaw(yaw) * fitted.rotation;
      const core::Pose chosen = estimator.NearestLookAlike(i, fitted);
      EXPECT_NEAR(core::AngleBetween(chosen.rotation, estimator.nominal(i).rotation), 0.2, 1e-6)
          << "body " << i << ", " << turn << " half turns";
      EXPECT_TRUE(chosen.translation.isApprox(fitted.translation));
      // Seen again, nearest where it was believed: here a quarter turn from the twin's own.
      core::Pose believed = estimator.nominal(i);
      believed.rotation = core::Yaw(M_PI / 2 + 0.1) * believed.rotation;
      const core::Pose again = estimator.NearestLookAlike(i, fitted, believed);
      EXPECT_NEAR(core::AngleBetween(again.rotation, believed.rotation), 0.1, 1e-6)
          << "body " << i << ", " << turn << " half turns";
    }

  auto spatula = std::make_shared<const sim::Task>(sim::LoadTaskSpec("spatula_flipping"));
  const ObjectPoseEstimator tools(spatula, {"spatula"});
  EXPECT_EQ(tools.symmetry(0), 1);
  core::Pose reversed = tools.nominal(0);
  reversed.rotation = core::Yaw(M_PI) * reversed.rotation;
  EXPECT_NEAR(
      core::AngleBetween(tools.NearestLookAlike(0, reversed).rotation, tools.nominal(0).rotation),
      M_PI, 1e-6)
      << "a spatula turned round is not the same spatula";
}

// Straight over the peg's block, a camera that sees the table under its walls sees through where
// the block would stand; not its top, the table down its hole or beside it. The table beside it is
// seen through the block moved there.
TEST(PoseEstimate, CountsThePointsSeenThroughWhereAnObjectWouldStand) {
  auto peg = std::make_shared<const sim::Task>(sim::LoadTaskSpec("peg_insertion"));
  const ObjectPoseEstimator estimator(peg, {"peg", "hole_block"});
  const core::Pose block = estimator.nominal(1);
  const Eigen::Vector3d camera = block * Eigen::Vector3d(0, 0, 0.5);
  // In the block's frame (its origin at its middle, 2 cm up): the table under each of its four
  // walls, each wall's top, the table down the hole, and the table 6 cm off its side.
  const double table = -0.02;
  std::vector<Eigen::Vector3d> under, top;
  for (const Eigen::Vector2d w : {Eigen::Vector2d(0.0215, 0), Eigen::Vector2d(-0.0215, 0),
                                  Eigen::Vector2d(0, 0.0215), Eigen::Vector2d(0, -0.0215)}) {
    under.push_back(block * Eigen::Vector3d(w.x(), w.y(), table));
    top.push_back(block * Eigen::Vector3d(w.x(), w.y(), 0.02));
  }
  const std::vector<Eigen::Vector3d> hole{block * Eigen::Vector3d(0, 0, table)};
  const std::vector<Eigen::Vector3d> beside{block * Eigen::Vector3d(0.0915, 0, table)};
  const double margin = 0.01;
  EXPECT_EQ(estimator.SeenThrough(1, block, camera, under, margin), 4);
  EXPECT_EQ(estimator.SeenThrough(1, block, camera, top, margin), 0);
  EXPECT_EQ(estimator.SeenThrough(1, block, camera, hole, margin), 0);
  EXPECT_EQ(estimator.SeenThrough(1, block, camera, beside, margin), 0);
  core::Pose moved = block;
  moved.translation.x() += 0.07;
  EXPECT_EQ(estimator.SeenThrough(1, moved, camera, beside, margin), 1);
  EXPECT_EQ(estimator.SeenThrough(1, moved, camera, top, margin), 0)
      << "short of where it would be";
  const Eigen::Vector3d from_afar = moved * Eigen::Vector3d(0, 0, 0.5);
  core::Pose away = moved;
  away.translation.y() += 0.2;
  EXPECT_EQ(estimator.SeenThrough(1, away, from_afar, under, margin), 0) << "the rays pass by";
  // Within the margin of its surface a point is not seen through it.
  EXPECT_EQ(
      estimator.SeenThrough(1, block, camera,
                            {block * Eigen::Vector3d(0.0215, 0, 0.02 - 0.5 * margin)}, margin),
      0);
}

}  // namespace
}  // namespace twinforge::samrl
