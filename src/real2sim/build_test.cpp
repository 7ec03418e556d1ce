#include "real2sim/build.h"

#include <gtest/gtest.h>

#include "core/test_support.h"
#include "real2sim/test_scenes.h"
#include "sim/mjcf.h"

namespace twinforge::real2sim {
namespace {

// From a scan to a twin the sim loads: a fixed fixture and a free object that rests on the
// exported table instead of falling through it.
TEST(Build, AScanBecomesATwinTheSimLoads) {
  const auto root = core::testing::TestDir("build_test");
  testing::SyntheticScan(root / "scan", R"(<mujoco><worldbody>
      <geom type="box" pos="0.5 0 -0.02" size="0.8 0.8 0.02" rgba="0.7 0.7 0.7 1"/>
      <geom type="box" pos="0.75 -0.1 0.1" size="0.17 0.17 0.1" rgba="0.6 0.45 0.3 1"/>
      <geom type="box" pos="0.5 0.2 0.04" size="0.03 0.03 0.04" rgba="0.2 0.4 0.8 1"/>
    </worldbody></mujoco>)",
                         {0.6, 0.05, 0.05}, 0.9);
  const auto report = BuildTwin(root / "scan", root / "twin", {});
  EXPECT_EQ(report["segments"].size(), 2u);
  for (const char* file : {"scan.ply", "twin.yaml", "scene.xml", "build.json",
                           "meshes/fixture_0.ply", "meshes/object_0.ply"})
    EXPECT_TRUE(std::filesystem::exists(root / "twin" / file)) << file;
  const TwinSpec spec = LoadTwinSpec(root / "twin" / "twin.yaml");
  ASSERT_EQ(spec.parts.size(), 2u);
  EXPECT_TRUE(spec.parts[0].fixed);
  EXPECT_FALSE(spec.parts[1].fixed);

  sim::MjcfParts parts;
  parts.robot = sim::LoadRobotSpec(sim::DefaultRobotPath()).mjcf_path();
  parts.scene = root / "twin" / "scene.xml";
  const sim::ModelPtr m = sim::LoadModelFromText(sim::AssembleMjcf(parts), "twin");
  const sim::DataPtr d = sim::MakeData(m.get());
  const int object = mj_name2id(m.get(), mjOBJ_BODY, "object_0");
  ASSERT_GE(object, 0);
  mj_forward(m.get(), d.get());
  const double z0 = d->xpos[3 * object + 2];
  for (int s = 0; s < 200; ++s) mj_step(m.get(), d.get());
  EXPECT_NEAR(d->xpos[3 * object + 2], z0, 0.01) << "rests on the table";
  EXPECT_NEAR(z0, 0.04, 0.01);
}

}  // namespace
}  // namespace twinforge::real2sim
