#include "reality/demos.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <numeric>

#include "core/test_support.h"
#include "reality/test_support.h"

namespace twinforge::reality {
namespace {

using namespace std::chrono_literals;

std::filesystem::path TempPath(const std::string& name) {
  const auto path = core::testing::TestDir("demos_test", name);
  std::filesystem::create_directories(path.parent_path());
  return path;
}

// Demos recorded through the bridge with the world's own operator land in robomimic layout and,
// replayed from their recorded seeds, do the task again, step for step.
TEST(Demos, RecordedOverTheBridgeInRobomimicLayoutAndReplayed) {
  const int port = testing::TestPort(11);
  testing::Served served(port);
  BridgeClient client(testing::Client(port, 20s));
  const sim::TaskSpec task = sim::LoadTaskSpec("open_drawer");  // the twin's task, not the world's
  RobotOperator op(client);
  RecordOptions options;
  options.demos = 3;
  options.seed = 5;
  options.valid_every = 3;
  options.cloud.scene_points = 512;
  options.cloud.arm_points = 128;
  const auto path = TempPath("real.hdf5");
  const RecordReport report = RecordDemos(client, op, task, options, path);
  EXPECT_EQ(report.kept, 3);
  EXPECT_LE(report.attempts, 4);
  EXPECT_GT(report.operator_seconds, 0.2 * report.steps);

  core::DatasetReader reader(path);
  ASSERT_EQ(reader.demos().size(), 3u);
  EXPECT_EQ(reader.env_args()["task"], "open_drawer");
  EXPECT_EQ(reader.env_args()["action_mode"], "discrete");
  EXPECT_EQ(reader.env_args()["source"], "proxy:open_drawer");
  EXPECT_EQ(reader.Mask("valid"), std::vector<std::string>{"demo_2"});
  EXPECT_EQ(reader.Mask("train").size(), 2u);

  ProxyReality replay(ResolveWorldDir("open_drawer"));
  ActionClient actions(replay, task.control.limits);
  for (const auto& name : reader.demos()) {
    const core::Episode e = reader.Read(name);
    const std::size_t t = e.length();
    ASSERT_GT(t, 10u);
    EXPECT_EQ(e.actions.shape, (std::vector<std::size_t>{t, 1}));
    EXPECT_EQ(e.obs.at("proprio").shape, (std::vector<std::size_t>{t, 9}));
    EXPECT_EQ(e.obs.at("joint_positions").shape, (std::vector<std::size_t>{t, 7}));
    EXPECT_EQ(e.obs.at("scene_points").shape, (std::vector<std::size_t>{t, 512, 3}));
    EXPECT_EQ(e.obs.at("arm_points").shape, (std::vector<std::size_t>{t, 128, 3}));
    EXPECT_EQ(e.rewards.back(), 1.0f);
    EXPECT_EQ(e.dones.back(), 1);
    ASSERT_TRUE(e.meta.contains("seed"));

    EXPECT_EQ(ReplayDemo(replay, task, e), SuccessAnswer::kSuccess) << name;
    // Step for step: the replayed arm passes through the recorded joint positions.
    Observation o = replay.Reset({e.meta["seed"].get<uint64_t>(), e.meta["level"].get<int>()});
    actions.ResetGripper();
    double worst = 0;
    for (std::size_t i = 0; i < t; ++i) {
      for (int k = 0; k < 7; ++k)
        worst = std::max(worst, std::abs(o.q[k] - e.obs.at("joint_positions").row(i)[k]));
      actions.Act(StoredAction(e, i), o);
      o = replay.Observe(false);
    }
    EXPECT_LT(worst, 1e-5) << name;
  }
}

TEST(Demos, RefusesToOverwriteAndNamesTheFile) {
  const auto path = TempPath("exists.hdf5");
  core::DatasetWriter::Create(path, {});
  ProxyReality proxy(ResolveWorldDir("open_drawer"));
  RobotOperator op(proxy);
  RecordOptions options;
  options.demos = 1;
  try {
    RecordDemos(proxy, op, sim::LoadTaskSpec("open_drawer"), options, path);
    FAIL() << "overwrote an existing dataset";
  } catch (const core::IoError& e) {
    EXPECT_NE(std::string(e.what()).find(path.string()), std::string::npos) << e.what();
  }
}

// The scene cloud comes from the camera with the arm cut out (its points come from forward
// kinematics instead).
TEST(FrameCloud, CutsTheArmOutOfTheDepth) {
  ProxyReality proxy(ResolveWorldDir("open_drawer"));
  const sim::TaskSpec task = sim::LoadTaskSpec("open_drawer");
  Observation o = proxy.Reset({3, 1});
  ActionClient actions(proxy, task.control.limits);
  for (int i = 0; i < 8; ++i) {  // bring the hand down, well into view
    actions.Act(sim::Action::Discrete(4), o);
    o = proxy.Observe(false);
  }
  const RgbdFrame frame = proxy.Frame();
  FrameCloud::Options options;
  options.scene_points = 4000;
  options.arm_points = 2000;
  FrameCloud cloud(sim::LoadRobotSpec(sim::DefaultRobotPath()), task.workspace, options);
  std::vector<float> scene(3 * 4000), arm(3 * 2000);
  core::Rng rng(1);
  cloud.Make(o, frame, rng, scene.data(), arm.data());

  // Points of a cloud within 1.5 cm of the arm's FK points.
  auto near_arm = [&](const float* points, int n) {
    int count = 0;
    for (int i = 0; i < n; ++i) {
      const Eigen::Vector3f p(points + 3 * i);
      for (int j = 0; j < 2000; ++j)
        if ((Eigen::Vector3f(arm.data() + 3 * j) - p).squaredNorm() < 0.015f * 0.015f) {
          ++count;
          break;
        }
    }
    return count;
  };
  std::vector<float> depth = DepthMetres(frame), raw(3 * depth.size());
  const sim::Camera camera{frame.intrinsics, frame.extrinsics};
  const int raw_n =
      sim::DepthToPoints(camera, depth.data(), sim::MakeWorkspace(task.workspace), raw.data());
  const int before = near_arm(raw.data(), raw_n);
  const int removed = cloud.RemoveArm(o, camera, depth);
  const int kept_n =
      sim::DepthToPoints(camera, depth.data(), sim::MakeWorkspace(task.workspace), raw.data());
  const int after = near_arm(raw.data(), kept_n);
  std::printf("arm: %d scene pixels near it before, %d after; %d removed\n", before, after,
              removed);
  ASSERT_GT(before, 40) << "the arm is in view";
  EXPECT_GE(removed, before);
  EXPECT_LT(after, before / 5);
  EXPECT_LT(near_arm(scene.data(), 4000), 4000 / 50);
}

// The drawer world's camera sits off its reported mount. With the mount's true error as the
// camera correction (what `twinforge calibrate` estimates), the table comes out flat: its points'
// heights spread by the sensor's noise, not by a tilted camera.
TEST(FrameCloud, TheCameraCorrectionPutsTheTableFlat) {
  ProxyReality proxy(ResolveWorldDir("open_drawer"));
  const sim::TaskSpec task = sim::LoadTaskSpec("open_drawer");
  const WorldSpec& world = proxy.spec();
  const core::Pose truth{Eigen::Vector3d(world.camera_offset.data()),
                         core::FromRollPitchYaw(world.camera_rotation[0], world.camera_rotation[1],
                                                world.camera_rotation[2])};
  const Observation o = proxy.Observe(false);
  const RgbdFrame frame = proxy.Frame();
  FrameCloud::Options options;
  options.scene_points = 3000;
  options.arm_points = 16;
  sim::WorkspaceSpec with_table = task.workspace;  // the task's crops the table away
  with_table.min[2] = -0.1;
  auto table_spread = [&](const core::Pose& correction) {
    FrameCloud cloud(sim::LoadRobotSpec(sim::DefaultRobotPath()), with_table, options, correction);
    std::vector<float> scene(3 * 3000), arm(3 * 16);
    core::Rng rng(1);
    cloud.Make(o, frame, rng, scene.data(), arm.data());
    std::vector<double> z;
    for (int i = 0; i < 3000; ++i)
      if (std::abs(scene[3 * i + 2]) < 0.04) z.push_back(scene[3 * i + 2]);
    const double mean = std::accumulate(z.begin(), z.end(), 0.0) / z.size();
    double var = 0;
    for (double v : z) var += (v - mean) * (v - mean);
    return std::sqrt(var / z.size());
  };
  const double reported = table_spread(core::Pose::Identity());
  const double corrected = table_spread(truth);
  EXPECT_LT(corrected, 0.5 * reported) << reported << " m spread at the reported pose";
  EXPECT_LT(corrected, 0.004);
}

}  // namespace
}  // namespace twinforge::reality
