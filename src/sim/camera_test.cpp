#include "sim/camera.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <filesystem>
#include <set>
#include <vector>

#include "core/error.h"
#include "core/fs.h"
#include "core/test_support.h"
#include "sim/env.h"
#include "sim/expert.h"
#include "sim/robot_mask.h"

namespace twinforge::sim {
namespace {

// A task whose scene is one box (half-size 5 cm at x = 0.55 m, z = 0.1 m) and no table.
std::shared_ptr<const Task> BoxTask() {
  const auto dir = core::testing::TestDir("camera_test");
  core::WriteFileAtomic(dir / "scene.xml", R"(<mujoco>
  <worldbody>
    <body name="block" pos="0.55 0 0.1">
      <geom name="block" type="box" size="0.05 0.05 0.05" rgba="1 0 0 1" group="2"/>
      <site name="a" pos="0 0 0"/><site name="b" pos="0 0 0.01"/>
    </body>
  </worldbody>
</mujoco>)");
  core::WriteFileAtomic(dir / "task.yaml", R"(name: box
scene: scene.xml
success: [{type: site_distance_below, site_a: a, site_b: b, threshold: 0.1}]
randomization: {distractors: {max_count: 0, count: [0, 0]}}
camera: {position: [1.2, 0.3, 0.6], look_at: [0.55, 0.0, 0.1], fovy_deg: 45, width: 80, height: 60}
workspace: {min: [0.3, -0.3, 0.02], max: [0.8, 0.3, 0.5]}
)");
  return std::make_shared<const Task>(LoadTaskSpec((dir / "task.yaml").string()));
}

// Distance from p to the box surface.
double BoxSurfaceDistance(const float* p) {
  const Eigen::Vector3d q =
      (Eigen::Vector3d(p[0], p[1], p[2]) - Eigen::Vector3d(0.55, 0, 0.1)).cwiseAbs() -
      Eigen::Vector3d::Constant(0.05);
  const double outside = q.cwiseMax(0.0).norm();
  const double inside = std::min(q.maxCoeff(), 0.0);
  return std::abs(outside + inside);
}

TEST(Camera, RenderedAndSyntheticPointsLieOnTheGeometry) {
  auto task = BoxTask();
  Env env(task);
  env.Reset(0, 0);
  for (bool rendered : {true, false}) {
    CloudMaker maker(*task, env.model(),
                     {.scene_points = 512, .arm_points = 256, .rendered = rendered});
    std::vector<float> scene(512 * 3), arm(256 * 3);
    core::Rng rng(1);
    maker.Make(env.model(), env.data(), env.base(), rng, scene.data(), arm.data());
    double worst = 0;
    for (int i = 0; i < 512; ++i) worst = std::max(worst, BoxSurfaceDistance(&scene[3 * i]));
    EXPECT_LT(worst, 2e-3) << (rendered ? "rendered" : "synthetic");
  }
}

TEST(Camera, ArmPointsComeFromForwardKinematicsNotDepth) {
  auto task = BoxTask();
  Env env(task);
  env.Reset(0, 0);
  CloudMaker maker(*task, env.model(), {.scene_points = 256, .arm_points = 256});
  std::vector<float> scene(256 * 3), arm(256 * 3);
  core::Rng rng(2);
  maker.Make(env.model(), env.data(), env.base(), rng, scene.data(), arm.data());
  // The gripper hangs above the box inside the workspace: arm points are near the tool.
  const Eigen::Vector3d tool = env.EePose().translation;
  int near_tool = 0;
  for (int i = 0; i < 256; ++i)
    near_tool += (Eigen::Vector3d(arm[3 * i], arm[3 * i + 1], arm[3 * i + 2]) - tool).norm() < 0.15;
  EXPECT_GT(near_tool, 50);
  // And no scene point is on the arm: every one is on the box.
  for (int i = 0; i < 256; ++i) ASSERT_LT(BoxSurfaceDistance(&scene[3 * i]), 2e-3);
}

// A step from 1 m to 1.5 m down the middle of the image, and a hole: the pixels either side of
// the step and around the hole are edges and all lose their return; a third of the others do;
// what is left is quantized to the millimetre.
TEST(Camera, DepthNoiseDropsEdgesAndQuantizes) {
  const int w = 40, h = 30;
  std::vector<float> depth(w * h);
  for (int v = 0; v < h; ++v)
    for (int u = 0; u < w; ++u) depth[v * w + u] = u < w / 2 ? 1.0f : 1.5f;
  depth[15 * w + 5] = 0;
  DepthNoise noise;
  noise.sigma0 = 0.002;
  noise.edge_dropout = 1.0;
  noise.dropout = 1.0 / 3;
  noise.quantization = 0.001;
  core::Rng rng(3);
  AddDepthNoise(depth.data(), w, h, noise, rng);
  int kept = 0, others = 0;
  for (int v = 0; v < h; ++v)
    for (int u = 0; u < w; ++u) {
      const float z = depth[v * w + u];
      const bool edge = u == w / 2 - 1 || u == w / 2 || (v == 15 && std::abs(u - 5) == 1) ||
                        (u == 5 && std::abs(v - 15) == 1);
      if (edge || (u == 5 && v == 15)) {
        EXPECT_EQ(z, 0.0f) << u << "," << v;
        continue;
      }
      ++others;
      if (z == 0) continue;
      ++kept;
      EXPECT_NEAR(z * 1000, std::round(z * 1000), 1e-3);
      EXPECT_NEAR(z, u < w / 2 ? 1.0 : 1.5, 0.01);
    }
  EXPECT_NEAR(double(kept) / others, 2.0 / 3, 0.06);
}

TEST(Camera, DepthEdgesAreStepsAndHolesNotSlopes) {
  // 5 x 3: a slope of 1 cm per pixel on the left, an 18 cm step between u = 2 and 3, a hole at
  // (4, 1).
  const int w = 5, h = 3;
  std::vector<float> depth(w * h);
  for (int v = 0; v < h; ++v)
    for (int u = 0; u < w; ++u) depth[v * w + u] = u < 3 ? 1.0f + 0.01f * u : 1.2f;
  depth[1 * w + 4] = 0;
  const std::vector<uint8_t> edge = DepthEdges(depth.data(), w, h, 0.05);
  const std::vector<uint8_t> want = {0, 0, 1, 1, 1,  //
                                     0, 0, 1, 1, 0,  // the hole itself is no edge
                                     0, 0, 1, 1, 1};
  EXPECT_EQ(edge, want);
  // With a threshold above the 18 cm step, only the hole's neighbours are edges.
  const std::vector<uint8_t> loose = DepthEdges(depth.data(), w, h, 0.5);
  const std::vector<uint8_t> want_loose = {0, 0, 0, 0, 1,  //
                                           0, 0, 0, 1, 0,  //
                                           0, 0, 0, 0, 1};
  EXPECT_EQ(loose, want_loose);
}

TEST(Camera, AShinySurfaceLosesItsOwnShareOfReturns) {
  // A flat 100 x 100 image: the left half sees geom 0, the right half geom 1, which the sensor
  // loses 60% of; 10% of every surface's returns are lost anyway.
  const int w = 100, h = 100;
  std::vector<float> depth(w * h, 1.0f);
  std::vector<int> geom(w * h);
  for (int i = 0; i < w * h; ++i) geom[i] = i % w < w / 2 ? 0 : 1;
  DepthNoise noise;
  noise.dropout = 0.1;
  core::Rng rng(5);
  AddDepthNoise(depth.data(), w, h, noise, rng, geom.data(), {0.0, 0.6});
  int kept[2] = {0, 0};
  for (int i = 0; i < w * h; ++i) kept[geom[i]] += depth[i] > 0;
  EXPECT_NEAR(kept[0] / (0.5 * w * h), 0.9, 0.02);
  EXPECT_NEAR(kept[1] / (0.5 * w * h), 0.9 * 0.4, 0.03);

  // By name, in a scene's geom ids; a name the scene lacks is named.
  const auto task = BoxTask();
  Env env(task);
  noise.surfaces = {{"block", 0.6}};
  const std::vector<double> by_geom = SurfaceDropoutByGeom(env.model(), noise);
  ASSERT_EQ(static_cast<int>(by_geom.size()), env.model()->ngeom);
  EXPECT_EQ(by_geom[mj_name2id(env.model(), mjOBJ_GEOM, "block")], 0.6);
  noise.surfaces = {{"blok", 0.6}};
  try {
    SurfaceDropoutByGeom(env.model(), noise);
    FAIL() << "an unknown geom was taken";
  } catch (const core::ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("'blok'"), std::string::npos) << e.what();
  }
}

TEST(Camera, DepthNoiseGrowsWithDistance) {
  std::vector<float> near(20000, 0.5f), far(20000, 1.5f);
  core::Rng rng(3);
  DepthNoise noise;
  noise.sigma_z2 = 0.004;
  AddDepthNoise(near.data(), 20000, 1, noise, rng);
  AddDepthNoise(far.data(), 20000, 1, noise, rng);
  auto stddev = [](const std::vector<float>& v, float mean) {
    double s = 0;
    for (float x : v) s += (x - mean) * (x - mean);
    return std::sqrt(s / v.size());
  };
  EXPECT_NEAR(stddev(near, 0.5f), 0.004 * 0.25, 1e-4);
  EXPECT_NEAR(stddev(far, 1.5f), 0.004 * 2.25, 5e-4);
}

TEST(Camera, RgbShowsTheObjectColour) {
  auto task = BoxTask();
  Env env(task);
  env.Reset(0, 0);
  RayCaster caster(MakeCamera(task->spec().camera), env.model());
  std::vector<float> depth(80 * 60);
  std::vector<uint8_t> rgb(80 * 60 * 3);
  caster.Render(env.model(), env.data(), env.base(), depth.data(), rgb.data());
  // The camera looks at the box: the centre pixel is red.
  const int centre = 30 * 80 + 40;
  EXPECT_GT(depth[centre], 0.0f);
  EXPECT_GT(rgb[3 * centre], 100);
  EXPECT_LT(rgb[3 * centre + 1], 20);
}

// The Embree scene must see what mj_ray sees: the same geom and the same depth (within the
// tessellation error) at nearly every pixel, in scenes with boxes, cylinders, spheres and the
// arm's capsules, with distractors resized at reset (level 2), robot shown and hidden.
TEST(Camera, EmbreeDepthMatchesMjRay) {
  for (const char* name : {"open_drawer", "mug_on_shelf", "peg_insertion"}) {
    auto task = std::make_shared<const Task>(LoadTaskSpec(name));
    Env env(task);
    env.Reset(3, 2);
    CameraSpec spec = task->spec().camera;
    spec.width = 160;
    spec.height = 120;
    RayCaster caster(MakeCamera(spec), env.model());
    const auto& k = caster.camera().intrinsics;
    for (bool robot : {false, true}) {
      std::vector<float> depth(k.width * k.height);
      caster.Render(env.model(), env.data(), env.base(), depth.data(), nullptr, robot);
      const core::Pose camera = env.base() * caster.camera().pose;
      mjtByte groups[mjNGROUP] = {1, 1, 1, 1, 1, 1};
      if (!robot) groups[kRobotGeomGroup] = 0;
      int agree = 0, hits = 0;
      for (int v = 0; v < k.height; ++v)
        for (int u = 0; u < k.width; ++u) {
          const Eigen::Vector3d ray =
              Eigen::Vector3d((u - k.cx) / k.fx, (v - k.cy) / k.fy, 1.0).normalized();
          const Eigen::Vector3d dir = camera.rotation * ray;
          int geom = -1;
          const double d = mj_ray(env.model(), env.data(), camera.translation.data(), dir.data(),
                                  groups, 1, -1, &geom);
          const double expected = geom >= 0 ? d * ray.z() : 0.0;
          hits += geom >= 0;
          agree += std::abs(depth[v * k.width + u] - expected) < 1e-3;
        }
      EXPECT_GT(hits, k.width * k.height / 2) << name;
      // Silhouette pixels of curved geoms may differ: the tessellation is inside the surface.
      EXPECT_GT(agree, 0.99 * k.width * k.height) << name << (robot ? " with robot" : "");
    }
  }
}

TEST(Camera, ACalibrationCorrectionMovesTheCameraInItsOwnFrame) {
  CameraSpec spec;
  const Camera nominal = MakeCamera(spec);
  spec.correction = {0.01, -0.02, 0.03, 0.004, -0.005, 0.006};
  const Camera corrected = MakeCamera(spec);
  // Moved by (0.004, -0.005, 0.006) along the camera's own axes, turned by 0.037 rad.
  EXPECT_LT(
      (corrected.pose.translation - nominal.pose * Eigen::Vector3d(0.004, -0.005, 0.006)).norm(),
      1e-12);
  EXPECT_NEAR(core::AngleBetween(corrected.pose.rotation, nominal.pose.rotation),
              std::sqrt(0.01 * 0.01 + 0.02 * 0.02 + 0.03 * 0.03), 1e-9);
  const auto back = CorrectionArray(CorrectionPose(spec.correction));
  for (int i = 0; i < 6; ++i) EXPECT_NEAR(back[i], spec.correction[i], 1e-12);
}

}  // namespace
}  // namespace twinforge::sim

namespace twinforge::sim {
namespace {

// What the camera at `spec` sees where the hole's top projects: the geom's name and the depth
// there against the hole's own depth (m).
struct AtTheHole {
  std::string geom;
  double depth = 0, hole_depth = 0;
};
AtTheHole LookAtTheHole(const char* task_name, const CameraSpec& spec, uint64_t seed) {
  auto task = std::make_shared<const Task>(LoadTaskSpec(task_name));
  Env env(task);
  env.Reset(seed, 1);
  RayCaster caster(MakeCamera(spec), env.model());
  const auto& k = caster.camera().intrinsics;
  std::vector<float> depth(k.width * k.height);
  std::vector<int> geom(k.width * k.height);
  caster.Render(env.model(), env.data(), env.base(), depth.data(), nullptr, true, geom.data());
  const int site = mj_name2id(env.model(), mjOBJ_SITE, "hole_top");
  const Eigen::Vector3d p = caster.camera().pose.Inverse() * env.SitePose(site).translation;
  const int u = int(std::lround(k.fx * p.x() / p.z() + k.cx));
  const int v = int(std::lround(k.fy * p.y() / p.z() + k.cy));
  EXPECT_TRUE(u >= 0 && u < k.width && v >= 0 && v < k.height) << task_name << " " << u << "," << v;
  const int i = v * k.width + u;
  const char* name = geom[i] >= 0 ? mj_id2name(env.model(), mjOBJ_GEOM, geom[i]) : nullptr;
  return {name ? name : "", depth[i], p.z()};
}

// The occluded variant hides the hole from the task camera behind its panel, at every level-1
// placement tried; without the panel the camera sees the hole, and a camera moved to the side
// sees it past the panel.
TEST(Camera, ThePanelHidesTheHoleFromTheTaskCameraOnly) {
  CameraSpec side = LoadTaskSpec("peg_insertion_occluded").camera;
  side.position = {0.55, 0.75, 0.5};
  side.look_at = {0.55, 0.15, 0.02};
  for (uint64_t seed = 1; seed <= 5; ++seed) {
    const AtTheHole hidden = LookAtTheHole("peg_insertion_occluded",
                                           LoadTaskSpec("peg_insertion_occluded").camera, seed);
    EXPECT_EQ(hidden.geom, "panel") << "seed " << seed;
    EXPECT_LT(hidden.depth, hidden.hole_depth - 0.1) << "seed " << seed;
    const AtTheHole plain =
        LookAtTheHole("peg_insertion", LoadTaskSpec("peg_insertion").camera, seed);
    EXPECT_NEAR(plain.depth, plain.hole_depth, 0.05) << "seed " << seed;
    const AtTheHole moved = LookAtTheHole("peg_insertion_occluded", side, seed);
    EXPECT_NE(moved.geom, "panel") << "seed " << seed;
    EXPECT_NEAR(moved.depth, moved.hole_depth, 0.05) << "seed " << seed;
  }
}

}  // namespace
}  // namespace twinforge::sim

namespace twinforge::sim {
namespace {

// The twin's rendered cloud is the cloud a real frame gives (reality::FrameCloud): the scene as
// the camera sees it with the arm in view, less the arm's pixels and the margin around them.
// With the gripper down at the drawer's bar, the cut takes the scene points around the hand;
// before, the twin's cloud showed the scene through the arm.
TEST(CloudMaker, CutsTheArmOutAsARealFrameIs) {
  const auto task = std::make_shared<const Task>(LoadTaskSpec("open_drawer"));
  Env env(task);
  env.Reset(4, 0);
  ScriptedExpert expert(*task);
  core::Rng rng(1);
  for (int t = 0; t < 80 && expert.current_step() < 2; ++t) env.Step(expert.Act(env, rng));
  ASSERT_GE(expert.current_step(), 2) << "the expert did not reach the bar";

  const Camera camera = MakeCamera(task->spec().camera);
  const int pixels = camera.intrinsics.width * camera.intrinsics.height;
  const Workspace workspace = MakeWorkspace(task->spec().workspace);
  auto points = [&](const std::vector<float>& depth) {
    std::vector<float> xyz(3 * pixels);
    xyz.resize(3 * DepthToPoints(camera, depth.data(), workspace, xyz.data()));
    std::set<std::array<float, 3>> unique;
    for (size_t i = 0; i < xyz.size(); i += 3) unique.insert({xyz[i], xyz[i + 1], xyz[i + 2]});
    return unique;
  };
  // As a real frame: rendered with the arm, the arm cut out as FrameCloud does.
  RayCaster caster(camera, env.model());
  std::vector<float> with_arm(pixels), without_arm(pixels);
  caster.Render(env.model(), env.data(), env.base(), with_arm.data(), nullptr, true);
  caster.Render(env.model(), env.data(), env.base(), without_arm.data(), nullptr, false);
  RobotMask mask(task->robot());
  mask.Pose(env.ArmPositions(), 2 * env.FingerOpening());
  ASSERT_GT(mask.Remove(camera, with_arm, kArmDepthMargin), 0);
  const auto real = points(with_arm);

  CloudMaker::Options options;
  options.scene_points = pixels;  // every point, plus repeats
  options.arm_points = 16;
  CloudMaker maker(*task, env.model(), options);
  std::vector<float> scene(3 * pixels), arm(3 * 16);
  maker.Make(env.model(), env.data(), env.base(), rng, scene.data(), arm.data());
  std::set<std::array<float, 3>> twin;
  for (int i = 0; i < pixels; ++i) twin.insert({scene[3 * i], scene[3 * i + 1], scene[3 * i + 2]});
  EXPECT_EQ(twin, real);
  // Measured: 658 scene points seen through the arm, 638 once cut.
  EXPECT_GT(points(without_arm).size(), real.size() + 10);
}

}  // namespace
}  // namespace twinforge::sim
