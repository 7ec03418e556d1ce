#include "samrl/active_camera.h"

#include <gtest/gtest.h>

#include "core/error.h"
#include "learn/torch_runtime.h"
#include "samrl/test_scenes.h"

namespace twinforge::samrl {
namespace {

using testing::Mount;
using testing::OccludedTarget;
using testing::Small;
using testing::VisibleTarget;

TEST(ActiveCamera, OrbitPoseLooksAtTheCentre) {
  const OrbitMount mount = Mount();
  for (double az : {-1.0, 0.0, 0.7})
    for (double el : {0.2, 0.9}) {
      const core::Pose pose = OrbitPose(mount, az, el);
      EXPECT_NEAR((pose.translation - mount.center).norm(), mount.radius, 1e-12);
      const Eigen::Vector3d forward = pose.rotation * Eigen::Vector3d::UnitZ();
      EXPECT_NEAR(forward.dot((mount.center - pose.translation).normalized()), 1.0, 1e-12);
      // The image's down axis points below the horizon: the picture is upright.
      EXPECT_LT((pose.rotation * Eigen::Vector3d::UnitY()).z(), 0);
      EXPECT_NEAR((pose.rotation * Eigen::Vector3d::UnitX()).z(), 0, 1e-12);
    }
}

// From a view with the target mostly behind the wall, ascent on the score through the renderer
// ends at the best view a dense grid finds (within 10%), and sampling gets near it too.
TEST(ActiveCamera, GradientAscentOnAKnownScoreFindsItsMaximum) {
  learn::PinMathThreads(1);
  const auto scene = OccludedTarget();
  const auto k = Small();
  const OrbitMount mount = Mount();
  double grid_best = 0;
  for (int i = 0; i <= 24; ++i)
    for (int j = 0; j <= 10; ++j) {
      const double az = mount.min_azimuth + (mount.max_azimuth - mount.min_azimuth) * i / 24;
      const double el = mount.min_elevation + (mount.max_elevation - mount.min_elevation) * j / 10;
      torch::NoGradGuard no_grad;
      grid_best = std::max(
          grid_best,
          VisibleTarget(real2sim::SoftRasterize(
                            scene, k, OrbitPose(mount, torch::tensor({az, el}, torch::kFloat64))))
              .item<double>());
    }
  ViewSearchOptions options;
  options.steps = 80;
  const ViewChoice ascent = AscendView(scene, k, mount, VisibleTarget, 0.15, 0.3, options);
  EXPECT_LT(ascent.scores.front(), 0.5 * grid_best) << "the start should be mostly occluded";
  EXPECT_GT(ascent.score, 0.9 * grid_best)
      << "from " << ascent.scores.front() << " to " << ascent.score << " at az " << ascent.azimuth
      << " el " << ascent.elevation << "; grid best " << grid_best;
  EXPECT_GE(ascent.azimuth, mount.min_azimuth);
  EXPECT_LE(ascent.elevation, mount.max_elevation);

  core::Rng rng(4);
  const ViewChoice sampled = SampleView(scene, k, mount, VisibleTarget, rng, options);
  EXPECT_EQ(sampled.scores.size(), 64u);
  EXPECT_GT(sampled.score, 0.8 * grid_best);
}

TEST(ActiveCamera, ABadMountIsRefused) {
  OrbitMount mount = Mount();
  mount.max_elevation = 1.6;
  EXPECT_THROW(AscendView(OccludedTarget(), Small(), mount, VisibleTarget, 0, 0.5), core::Error);
}

}  // namespace
}  // namespace twinforge::samrl
