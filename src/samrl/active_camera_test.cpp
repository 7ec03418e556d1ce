#include "samrl/active_camera.h"

#include <gtest/gtest.h>

#include "core/error.h"
#include "learn/torch_runtime.h"

namespace twinforge::samrl {
namespace {

using real2sim::BoxMesh;

// A red target on a blue table behind a blue wall on its +x side: seen from +x (azimuth 0) the
// wall hides it; seen from the sides or from above it is in full view.
real2sim::RasterMesh OccludedTarget() {
  const Eigen::Vector3d blue(0, 0, 1), red(1, 0, 0);
  return real2sim::JoinMeshes({BoxMesh({0.5, 0, -0.02}, {0.8, 0.8, 0.04}, blue),
                               BoxMesh({0.5, 0, 0.04}, {0.08, 0.08, 0.08}, red),
                               BoxMesh({0.62, 0, 0.12}, {0.03, 0.5, 0.24}, blue)});
}

core::PinholeIntrinsics Small() {
  core::PinholeIntrinsics k;
  k.width = 40;
  k.height = 30;
  k.fx = k.fy = 40;
  k.cx = 19.5;
  k.cy = 14.5;
  return k;
}

// A known score: how much of the image the red target covers.
torch::Tensor VisibleTarget(const real2sim::SoftImage& image) {
  return image.rgb.select(2, 0).mean() * 100.0;
}

OrbitMount Mount() {
  OrbitMount m;
  m.center = Eigen::Vector3d(0.5, 0, 0.05);
  m.radius = 0.7;
  m.min_azimuth = -1.2;
  m.max_azimuth = 1.2;
  m.min_elevation = 0.15;
  m.max_elevation = 1.2;
  return m;
}

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
