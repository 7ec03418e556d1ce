// The point clouds a policy sees, made from what a robot reports, the same two clouds
// sim::CloudMaker makes in the twin: scene points back-projected from a depth frame with its
// reported intrinsics and extrinsics, cropped to the task's workspace, with the arm's own pixels
// removed; and arm points sampled on the arm at its measured joint positions (forward
// kinematics), never taken from depth.
#pragma once

#include <vector>

#include "core/rng.h"
#include "reality/robot.h"
#include "sim/camera.h"
#include "sim/robot.h"
#include "sim/robot_mask.h"

namespace twinforge::reality {

class FrameCloud {
 public:
  struct Options {
    int scene_points = 2048;
    int arm_points = 512;
    double arm_margin = sim::kArmDepthMargin;  // m: depth this close to (or behind) the arm
  };
  // `camera_correction`: the camera's calibration (sim::CameraSpec::correction as a pose): a
  // frame's reported extrinsics are composed with it before back-projecting.
  FrameCloud(const sim::RobotSpec& robot, const sim::WorkspaceSpec& workspace,
             const Options& options, const core::Pose& camera_correction = core::Pose::Identity());
  ~FrameCloud();

  // Fills scene[scene_points*3] and arm[arm_points*3], robot base frame.
  void Make(const Observation& observation, const RgbdFrame& frame, core::Rng& rng, float* scene,
            float* arm);
  // Removes the arm from a depth image (metres, in place): pixels where the arm, posed at the
  // observation's joints, is in front of or at the measured depth. Returns how many.
  int RemoveArm(const Observation& observation, const sim::Camera& camera,
                std::vector<float>& depth);
  const Options& options() const { return options_; }

 private:
  Options options_;
  core::Pose camera_correction_;
  sim::Workspace workspace_;
  sim::RobotMask robot_;
  std::vector<float> depth_, scratch_;
};

// A frame's depth in metres (0 = no return).
std::vector<float> DepthMetres(const RgbdFrame& frame);

}  // namespace twinforge::reality
