#include "real2sim/fusion.h"

#include <gtest/gtest.h>

#include "core/rng.h"
#include "core/test_support.h"
#include "real2sim/test_scenes.h"

namespace twinforge::real2sim {
namespace {

constexpr double kYaw = 0.3;
const Eigen::Vector3d kBoxCentre(0.6, 0.05, 0.05), kBoxHalf(0.1, 0.075, 0.05);

// Points on the box's five visible faces (not the bottom).
std::vector<Eigen::Vector3d> BoxSurface() {
  std::vector<Eigen::Vector3d> points;
  const Eigen::Matrix3d r = Eigen::AngleAxisd(kYaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  core::Rng rng(9);
  while (points.size() < 20000) {
    Eigen::Vector3d local(rng.Uniform(-1, 1), rng.Uniform(-1, 1), rng.Uniform(-1, 1));
    const int axis = static_cast<int>(rng.Index(3));
    local[axis] = rng.Uniform() < 0.5 ? -1 : 1;
    if (axis == 2 && local[2] < 0) continue;
    points.push_back(kBoxCentre + r * local.cwiseProduct(kBoxHalf));
  }
  return points;
}

TEST(Fusion, RecoversAKnownBoxAndItsTable) {
  const auto dir = core::testing::TestDir("fusion_test");
  testing::SyntheticScan(dir, R"(<mujoco><compiler angle="radian"/><worldbody>
      <geom type="box" pos="0.5 0 -0.02" size="0.8 0.8 0.02" rgba="0.7 0.7 0.7 1"/>
      <geom type="box" pos="0.6 0.05 0.05" size="0.1 0.075 0.05" euler="0 0 0.3"
            rgba="0.8 0.3 0.2 1"/>
    </worldbody></mujoco>)",
                         {0.6, 0.05, 0.05});
  const Fusion fusion =
      FuseScan(core::ReadScan(dir), sim::LoadRobotSpec(sim::DefaultRobotPath()), {});
  ASSERT_FALSE(fusion.mesh.empty());
  // The table top is z = 0.
  EXPECT_GT(fusion.support.normal.z(), std::cos(0.5 * M_PI / 180));
  EXPECT_NEAR(fusion.support.offset, 0.0, 0.002);
  // What stands on it is the box, within a few mm.
  std::vector<Eigen::Vector3d> above;
  for (const auto& p : fusion.points)
    if (fusion.support.Distance(p) > 0.01 && (p - kBoxCentre).norm() < 0.3) above.push_back(p);
  ASSERT_GT(above.size(), 1000u);
  const double chamfer = ChamferDistance(above, BoxSurface());
  std::printf("box: %zu points, Chamfer %.2f mm; %ld robot pixels cut\n", above.size(),
              1e3 * chamfer, fusion.robot_pixels);
  EXPECT_LT(chamfer, 0.003);
  WriteMesh(dir / "fused.ply", fusion.mesh);
  const Mesh back = ReadMesh(dir / "fused.ply");
  EXPECT_EQ(back.triangles.size(), fusion.mesh.triangles.size());
}

TEST(Fusion, SupportPlaneIgnoresWallsAndClutter) {
  std::vector<Eigen::Vector3d> points;
  core::Rng rng(4);
  for (int i = 0; i < 3000; ++i)  // a table at z = 0.1, slightly tilted
    points.emplace_back(rng.Uniform(0, 1), rng.Uniform(-0.5, 0.5),
                        0.1 + 0.01 * points.size() / 3000.0);
  for (int i = 0; i < 4000; ++i)  // a bigger wall
    points.emplace_back(1.0, rng.Uniform(-0.5, 0.5), rng.Uniform(0, 1));
  for (int i = 0; i < 1000; ++i)  // clutter
    points.emplace_back(rng.Uniform(0, 1), rng.Uniform(-0.5, 0.5), rng.Uniform(0.1, 0.5));
  const Plane plane = FitSupportPlane(points, 0.004, 0.35, 1);
  EXPECT_GT(plane.normal.z(), 0.999);
  EXPECT_NEAR(plane.Distance(Eigen::Vector3d(0.5, 0, 0.105)), 0.0, 0.003);
}

}  // namespace
}  // namespace twinforge::real2sim
