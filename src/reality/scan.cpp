#include "reality/scan.h"

#include <cmath>

#include "core/error.h"
#include "core/log.h"
#include "core/rng.h"
#include "sim/camera.h"
#include "sim/robot.h"

namespace twinforge::reality {

namespace {

// A frame's index entry: where the camera was said to be, and the arm's joints.
core::ScanFrameInfo FrameInfo(const Observation& o, const RgbdFrame& frame) {
  core::ScanFrameInfo f;
  f.stamp = frame.stamp;
  f.intrinsics = frame.intrinsics;
  f.camera_to_base = frame.extrinsics;
  std::copy(o.q.data(), o.q.data() + sim::kArmDof, f.joint_positions.begin());
  f.gripper_width = o.gripper_width;
  return f;
}

sim::CameraSpec ScanCameraSpec(const ScanOptions& o) {
  sim::CameraSpec spec;
  spec.name = "scan";
  spec.fovy_deg = o.fovy_deg;
  spec.width = o.width;
  spec.height = o.height;
  return spec;
}

}  // namespace

sim::CameraIntrinsics ScanIntrinsics(const ScanOptions& options) {
  return sim::MakeCamera(ScanCameraSpec(options)).intrinsics;
}

std::vector<core::Pose> ScanPath(const sim::TaskSpec& task, const ScanOptions& options) {
  const Eigen::Vector3d center(task.camera.look_at.data());
  const Eigen::Vector3d from = Eigen::Vector3d(task.camera.position.data()) - center;
  const double radius = options.radius > 0 ? options.radius : from.norm();
  const double azimuth0 = std::atan2(from.y(), from.x());
  const double span = options.azimuth_span_deg * M_PI / 180.0;
  std::vector<core::Pose> path;
  for (std::size_t ring = 0; ring < options.elevations_deg.size(); ++ring) {
    const double elevation = options.elevations_deg[ring] * M_PI / 180.0;
    // Rings run in alternate directions, as a camera on an arm would sweep.
    for (int i = 0; i < options.frames_per_ring; ++i) {
      const int k = ring % 2 == 0 ? i : options.frames_per_ring - 1 - i;
      const double f =
          options.frames_per_ring > 1 ? double(k) / (options.frames_per_ring - 1) : 0.5;
      const double azimuth = azimuth0 + (f - 0.5) * span;
      const Eigen::Vector3d position =
          center + radius * Eigen::Vector3d(std::cos(elevation) * std::cos(azimuth),
                                            std::cos(elevation) * std::sin(azimuth),
                                            std::sin(elevation));
      sim::CameraSpec spec = ScanCameraSpec(options);
      spec.position = {position.x(), position.y(), position.z()};
      spec.look_at = task.camera.look_at;
      path.push_back(sim::MakeCamera(spec).pose);
    }
  }
  return path;
}

core::Scan CaptureScan(Robot& robot, const std::vector<core::Pose>& path,
                       const sim::CameraIntrinsics& intrinsics, const std::filesystem::path& out,
                       core::Progress* progress) {
  const RobotInfo info = robot.Info();
  if (!info.can_scan)
    throw core::Error(info.name +
                      " cannot move a camera to scan; take the frames with a hand-held RGB-D "
                      "camera and write them in the layout of docs/scan.md");
  core::ScanWriter writer(out, info.name, info.robot);
  for (const core::Pose& pose : path) {
    const Observation o = robot.Observe(false);
    const RgbdFrame frame = robot.Capture({pose, intrinsics});
    writer.Add(FrameInfo(o, frame), frame.rgb, frame.depth);
    if (progress) progress->Advance();
  }
  return writer.scan();
}

core::Scan CaptureCameraFrames(Robot& robot, const sim::Kinematics& kinematics,
                               const Eigen::Vector3d& centre, int count, double spread,
                               uint64_t seed, const std::filesystem::path& out,
                               core::Progress* progress) {
  if (count < 1) throw core::ConfigError("camera frames", "count", "at least one frame");
  const RobotInfo info = robot.Info();
  if (info.cameras.empty()) throw core::Error(info.name + " reports no camera to calibrate");
  core::ScanWriter writer(out, info.name, info.robot);
  core::Rng rng(seed, 0xf4a3);
  const int settle = std::max(1, static_cast<int>(std::ceil(1.5 / info.control_period)));
  const double finger = 0.5 * robot.Observe(false).gripper_width;  // the fingers stay as they are
  const sim::ArmVector home = kinematics.home();
  const core::Quat orientation = kinematics.EePose(home).rotation;
  // Targets move from where the arm is to the goal over the first two thirds of the settling
  // time, then hold: no jump for the arm's controller to chase.
  auto move_to = [&](const sim::ArmVector& goal) {
    const sim::ArmVector from = robot.Observe(false).q;
    sim::JointTargets targets;
    targets.finger = finger;
    const double ramp = std::max(1.0, 2.0 * settle / 3.0);
    for (int k = 0; k < settle; ++k) {
      targets.arm = from + std::min(1.0, (k + 1) / ramp) * (goal - from);
      robot.SendTargets(targets);
    }
  };
  for (int i = 0; i < count; ++i) {
    sim::ArmVector goal = home;
    if (i > 0) {
      const Eigen::Vector3d offset(rng.Uniform(-spread, spread), rng.Uniform(-spread, spread),
                                   rng.Uniform(0, spread));
      goal = kinematics.SolveIk(home, {centre + offset, orientation});
    }
    move_to(goal);
    const Observation o = robot.Observe(true);
    if (o.frames.empty()) throw core::Error(info.name + " sent no camera frame");
    const RgbdFrame& frame = o.frames.front();
    writer.Add(FrameInfo(o, frame), frame.rgb, frame.depth);
    if (progress) progress->Advance();
  }
  move_to(home);
  return writer.scan();
}

int OperateThenHome(Robot& robot, Operator& op, const sim::TaskSpec& task) {
  const RobotInfo info = robot.Info();
  ActionClient client(robot, task.control.limits);
  Observation o = robot.Observe(false);
  const int actions = RunOperator(robot, op, client, o, 3 * task.horizon, false).actions;
  const SuccessAnswer answer = robot.QuerySuccess();
  if (answer != SuccessAnswer::kUnknown)
    spdlog::info("scan: the robot reports the operator's run a {}", ToString(answer));
  // Home in small joint steps (the safety filter's per-step limit is for actions; a straight
  // interpolation in joint space keeps each step as small).
  const sim::RobotSpec spec = sim::LoadRobotSpec(RobotDescriptionPath(info.robot));
  const sim::ArmVector start = o.q, home(spec.home.data());
  const int steps = 30;
  for (int i = 1; i <= steps + 10; ++i) {
    const double f = std::min(1.0, double(i) / steps);
    robot.SendTargets({start + f * (home - start), spec.gripper_open, 0.0});
  }
  o = robot.Observe(false);
  spdlog::info("scan: the operator sent {} actions; the arm is {:.3f} rad from home", actions,
               (o.q - home).norm());
  return actions;
}

}  // namespace twinforge::reality
