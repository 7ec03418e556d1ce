#include "real2sim/calibrate/calibrate.h"

#include <gtest/gtest.h>

#include "core/config.h"
#include "core/error.h"
#include "core/image.h"
#include "core/test_support.h"
#include "learn/torch_runtime.h"
#include "reality/proxy_reality.h"
#include "reality/scan.h"
#include "sim/camera.h"

namespace twinforge::real2sim {
namespace {

// Frames of the proxy drawer world's fixed camera, which sits 2 cm and 2.7 deg off where it
// reports (the test reads the world for its scene; the pipeline never does).
core::Scan DrawerFrames(const std::filesystem::path& dir, int count) {
  reality::ProxyReality robot(reality::ResolveWorldDir("open_drawer"));
  const sim::TaskSpec task = sim::LoadTaskSpec("open_drawer");
  const sim::Kinematics kinematics(sim::LoadRobotSpec(sim::DefaultRobotPath()));
  return reality::CaptureCameraFrames(robot, kinematics,
                                      Eigen::Vector3d(task.camera.look_at.data()) +
                                          Eigen::Vector3d(0, 0, reality::kCameraFramesHeight),
                                      count, reality::kCameraFramesSpread, 1, dir);
}

double MeanMedian(const std::vector<FrameFit>& fits) {
  double sum = 0;
  for (const auto& f : fits) sum += f.median_depth_error;
  return sum / fits.size();
}

TEST(CalibrateCamera, BringsTheTwinOntoTheFramesAndWritesTheCorrectedTwin) {
  learn::PinMathThreads(1);
  const auto dir = core::testing::TestDir("calibrate");
  const core::Scan frames = DrawerFrames(dir / "frames", 3);
  ASSERT_EQ(frames.frames.size(), 3u);
  const auto world = reality::ResolveWorldDir("open_drawer");
  const sim::TaskSpec twin = sim::LoadTaskSpec((world / "task.yaml").string());
  CalibrateOptions options;
  options.solver = "adam";
  options.iterations = 40;
  options.mesh_triangles = 300;
  const CameraCalibration c = CalibrateCamera(twin, frames, options);
  ASSERT_EQ(c.before.size(), 3u);
  ASSERT_EQ(c.after.size(), 3u);
  // From the reported pose the twin is ~1.5 cm off the real depth; calibrated, under half that.
  EXPECT_GT(MeanMedian(c.before), 0.008);
  EXPECT_LT(MeanMedian(c.after), 0.5 * MeanMedian(c.before));
  for (size_t i = 0; i < 3; ++i) EXPECT_GE(c.after[i].inliers, c.before[i].inliers - 0.01);
  EXPECT_LT(c.loss.back(), c.loss.front());

  // The refined twin's camera carries the correction; its sim camera moves by it.
  WriteCalibratedTwin(world, frames, c, options, dir / "calibrated");
  const sim::TaskSpec refined = sim::LoadTaskSpec((dir / "calibrated/task.yaml").string());
  const core::Pose moved = sim::MakeCamera(refined.camera).pose;
  const core::Pose expected = sim::MakeCamera(twin.camera).pose * c.correction;
  EXPECT_LT((moved.translation - expected.translation).norm(), 1e-9);
  EXPECT_LT(core::AngleBetween(moved.rotation, expected.rotation), 1e-9);
  // ... and the sensor's noise as measured, which its rendered clouds then get.
  EXPECT_GT(c.noise.edge_dropout, 0.0);
  EXPECT_EQ(refined.camera.noise.edge_dropout, c.noise.edge_dropout);
  EXPECT_EQ(refined.camera.noise.sigma0, c.noise.sigma0);
  EXPECT_TRUE(std::filesystem::exists(dir / "calibrated/calibration/frame_02.png"));
  EXPECT_TRUE(std::filesystem::exists(dir / "calibrated/calibration/calibration.json"));
  std::filesystem::remove_all(dir);
}

// The grader's view: the world's true mount, read from its hidden settings.
core::Pose TrueCorrection(const std::string& world) {
  const reality::WorldSpec spec = reality::LoadWorldSpec(reality::ResolveWorldDir(world));
  return {Eigen::Vector3d(spec.camera_offset.data()),
          core::FromRollPitchYaw(spec.camera_rotation[0], spec.camera_rotation[1],
                                 spec.camera_rotation[2])};
}

TEST(CalibrateCamera, GaussNewtonFindsTheMountWithinAFewMillimetres) {
  learn::PinMathThreads(1);
  const auto dir = core::testing::TestDir("calibrate_gn");
  const core::Scan frames = DrawerFrames(dir / "frames", 16);
  const sim::TaskSpec twin =
      sim::LoadTaskSpec((reality::ResolveWorldDir("open_drawer") / "task.yaml").string());
  const CameraCalibration c = CalibrateCamera(twin, frames, {});
  const core::Pose truth = TrueCorrection("open_drawer");
  ASSERT_GT(truth.translation.norm(), 0.02);  // the start: 21.7 mm and 2.5 deg off
  const core::Pose error = c.correction.Inverse() * truth;
  const core::Pose icp_error = c.icp_correction.Inverse() * truth;
  std::printf("camera error: ours %.2f mm %.3f deg, ICP %.2f mm %.3f deg\n",
              1e3 * error.translation.norm(),
              core::AngleBetween(error.rotation, core::Quat::Identity()) * 180 / M_PI,
              1e3 * icp_error.translation.norm(),
              core::AngleBetween(icp_error.rotation, core::Quat::Identity()) * 180 / M_PI);
  // The target: 5 mm and 1 deg. Measured: 2.95 mm and 0.30 deg (8 frames: 4.7 mm;
  // Gauss-Newton with soft edges of 0.3 px and 600-triangle meshes, 8 frames: 6.3 mm; Adam on
  // depth + EMD: 23 mm). ICP is lost on this scene (38 mm): the world's own meshes, decimated.
  EXPECT_LT(error.translation.norm(), 0.005);
  EXPECT_LT(core::AngleBetween(error.rotation, core::Quat::Identity()), 1.0 * M_PI / 180);
  EXPECT_LT(c.loss.back(), c.loss.front());
  // The sensor's noise against the world's hidden one: half the returns lost at depth edges,
  // few elsewhere (the shiny bar, dark spots), and sigma = 1 mm + 2 mm / m^2 * z^2 at the
  // 0.8-1.1 m the scene lies at (2.3-3.4 mm), quantized to 1 mm.
  EXPECT_GT(c.noise.edge_dropout, 0.35) << core::ToJson(c.noise).dump();
  EXPECT_LT(c.noise.edge_dropout, 0.75) << core::ToJson(c.noise).dump();
  EXPECT_LT(c.noise.dropout, 0.2) << core::ToJson(c.noise).dump();
  EXPECT_GT(c.noise.sigma0, 0.0015) << core::ToJson(c.noise).dump();
  EXPECT_LT(c.noise.sigma0, 0.005) << core::ToJson(c.noise).dump();
  // The handle (one steel mesh in this twin, the world's own scene) is shiny: the hidden sensor
  // loses half the returns the edges leave on it. It is the one surface listed, with about that
  // (measured: 40% on 104 pixels).
  ASSERT_EQ(c.noise.surfaces.size(), 1u) << core::ToJson(c.noise).dump();
  EXPECT_EQ(c.noise.surfaces[0].geom, "handle");
  EXPECT_GT(c.noise.surfaces[0].dropout, 0.25) << core::ToJson(c.noise).dump();
  EXPECT_LT(c.noise.surfaces[0].dropout, 0.75) << core::ToJson(c.noise).dump();
  std::filesystem::remove_all(dir);
}

TEST(CalibrateCamera, AFrameOfTheWrongSizeIsNamed) {
  const auto dir = core::testing::TestDir("calibrate_bad");
  core::Scan frames = DrawerFrames(dir / "frames", 1);
  core::WritePng(frames.dir / frames.frames[0].depth,
                 {10, 10, 1, 16, std::vector<uint8_t>(200, 0)});
  const sim::TaskSpec twin =
      sim::LoadTaskSpec((reality::ResolveWorldDir("open_drawer") / "task.yaml").string());
  try {
    CalibrateCamera(twin, frames, {});
    FAIL() << "a 10x10 depth image was taken for an 80x60 frame";
  } catch (const core::ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find(frames.frames[0].depth), std::string::npos) << e.what();
  }
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace twinforge::real2sim
