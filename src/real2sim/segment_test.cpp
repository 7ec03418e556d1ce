#include "real2sim/segment.h"

#include <gtest/gtest.h>

#include "core/rng.h"
#include "core/test_support.h"
#include "real2sim/test_scenes.h"

namespace twinforge::real2sim {
namespace {

// A chest-sized fixture and a mug-sized object on a table come apart: two segments of the right
// kinds and sizes, each with its own mesh within the budget; the table is the static scene.
TEST(Segment, SplitsAFixtureAndAMovableObject) {
  const auto dir = core::testing::TestDir("segment_test");
  testing::SyntheticScan(dir, R"(<mujoco><worldbody>
      <geom type="box" pos="0.5 0 -0.02" size="0.8 0.8 0.02" rgba="0.7 0.7 0.7 1"/>
      <geom type="box" pos="0.75 -0.1 0.1" size="0.17 0.17 0.1" rgba="0.6 0.45 0.3 1"/>
      <geom type="cylinder" pos="0.5 0.2 0.05" size="0.03 0.05" rgba="0.2 0.4 0.8 1"/>
    </worldbody></mujoco>)",
                         {0.6, 0.05, 0.05}, 0.9);
  const Fusion fusion =
      FuseScan(core::ReadScan(dir), sim::LoadRobotSpec(sim::DefaultRobotPath()), {});
  SegmentOptions options;
  options.triangle_budget = 800;
  const Segmentation seg = SegmentScene(fusion, options);
  ASSERT_EQ(seg.segments.size(), 2u);
  const Segment& chest = seg.segments[0];
  const Segment& mug = seg.segments[1];
  EXPECT_EQ(chest.name, "fixture_0");
  EXPECT_FALSE(chest.movable);
  EXPECT_EQ(mug.name, "object_0");
  EXPECT_TRUE(mug.movable);
  // Extents within a few mm (the bottom few mm sit below the height cut).
  EXPECT_NEAR(mug.max.z(), 0.10, 0.005);
  EXPECT_NEAR(mug.max.x() - mug.min.x(), 0.06, 0.008);
  EXPECT_NEAR(mug.max.y() - mug.min.y(), 0.06, 0.008);
  EXPECT_NEAR(chest.max.z(), 0.20, 0.005);
  EXPECT_NEAR(chest.max.x() - chest.min.x(), 0.34, 0.01);
  for (const auto& s : seg.segments) {
    EXPECT_FALSE(s.mesh.empty()) << s.name;
    EXPECT_LE(s.mesh.triangles.size(), 800u) << s.name;
  }
  EXPECT_FALSE(seg.static_scene.empty());
  EXPECT_LT(seg.static_scene.max().z(), 0.02) << "only the table is static";
}

// A sheet of the table's depth noise, 9-15 mm up and chained over half a metre with a tenth of
// its points higher still (as scans at home left beside the drawer world's chest, whose 128
// collision boxes slowed its physics tenfold, and beside the peg), is not an object; a 5 cm
// block beside it is.
TEST(Segment, ASheetOfTableNoiseIsNotAnObject) {
  Fusion fusion;
  core::Rng rng(3);
  for (double x = -0.3; x < 0.3; x += 0.006)
    for (double y = -0.8; y < -0.4; y += 0.006) {
      const bool outlier = rng.Uniform(0, 1) < 0.1;
      fusion.points.emplace_back(x, y,
                                 outlier ? rng.Uniform(0.021, 0.028) : rng.Uniform(0.009, 0.015));
    }
  for (double x = 0.5; x < 0.56; x += 0.005)
    for (double y = 0.0; y < 0.06; y += 0.005)
      for (double z = 0.01; z <= 0.051; z += 0.005) fusion.points.emplace_back(x, y, z);
  const Segmentation seg = SegmentScene(fusion, SegmentOptions{});
  ASSERT_EQ(seg.segments.size(), 1u);
  EXPECT_TRUE(seg.segments[0].movable);
  EXPECT_NEAR(seg.segments[0].min.x(), 0.5, 1e-9);
}

}  // namespace
}  // namespace twinforge::real2sim
