// The only way the pipeline touches reality: a robot arm with an RGB-D camera, real or the proxy
// reality, in-process or over the bridge (reality/bridge.h).
//
// A robot takes joint targets and reports joint state and camera frames. Actions (end-effector
// deltas, continuous or RialTo's discrete moves) become joint targets on the client side, in
// Robot::Act: the safety filter, then sim::ActionToJointTargets with the robot's kinematics, the
// same function the twin uses. So a driver for a real arm only has to follow joint targets.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/se3.h"
#include "reality/safety_filter.h"
#include "sim/action.h"
#include "sim/camera.h"

namespace twinforge::reality {

// One RGB-D frame as the camera driver reports it.
struct RgbdFrame {
  std::string camera;
  double stamp = 0;  // s, robot clock
  sim::CameraIntrinsics intrinsics;
  core::Pose extrinsics;        // camera (OpenCV axes) -> robot base, as calibrated
  std::vector<uint8_t> rgb;     // width*height*3
  std::vector<uint16_t> depth;  // width*height, millimetres along the optical axis, 0 = none
};

struct Observation {
  double stamp = 0;  // s, robot clock
  sim::ArmVector q = sim::ArmVector::Zero(), qd = sim::ArmVector::Zero();
  double gripper_width = 0;  // m between the fingers
  core::Pose ee;             // tool centre point in the robot base frame
  std::vector<RgbdFrame> frames;
};

// What a robot says about itself once, on connection.
struct RobotInfo {
  std::string name;             // e.g. "proxy:open_drawer" or "panda@lab-3"
  std::string robot;            // robot description name under assets/robots ("panda")
  double control_period = 0.1;  // s between actions
  std::vector<std::string> cameras;
  bool has_success_oracle = false;  // only the proxy reality can tell success by itself
  bool can_scan = false;            // answers Capture (a wrist or scan camera it can move)
  bool has_operator = false;        // answers AskOperator (the proxy's scripted operator)
};

// A scan frame: the scan camera brought to `pose` (camera, OpenCV axes -> robot base) and one
// frame taken with `intrinsics`. A real robot moves its wrist camera there; the frame's
// extrinsics are where the robot believes the camera ended up, which is not exactly where it is.
struct CaptureRequest {
  core::Pose pose;
  sim::CameraIntrinsics intrinsics;
};

// What the person at the controls does next.
struct OperatorInput {
  enum class Kind { kAction, kIdle, kDone, kQuit };
  Kind kind = Kind::kIdle;  // a key for a move or the gripper; nothing; "it's done"; stop recording
  sim::Action action;       // when kind == kAction
  double think = 0;         // s the person took to decide (hesitations included)
};
const char* ToString(OperatorInput::Kind kind);

enum class SuccessAnswer { kSuccess, kFailure, kUnknown };
const char* ToString(SuccessAnswer answer);

// Reset request: a person resets a real scene (seed and level are hints); the proxy reality
// resamples its scene from them.
struct ResetRequest {
  uint64_t seed = 0;
  int level = 1;
};

class Robot {
 public:
  virtual ~Robot() = default;

  virtual RobotInfo Info() = 0;
  // Current state; camera frames only when asked (they are the expensive part).
  virtual Observation Observe(bool with_frames) = 0;
  // Follow these joint targets for one control period.
  virtual void SendTargets(const sim::JointTargets& targets) = 0;
  virtual Observation Reset(const ResetRequest& request) = 0;
  virtual SuccessAnswer QuerySuccess() = 0;
  // One scan frame (Info().can_scan). The default says the robot cannot scan.
  virtual RgbdFrame Capture(const CaptureRequest& request);
  // The next input of the robot's own operator (Info().has_operator): the proxy reality's
  // scripted operator, who watches the scene. The default says there is none.
  virtual OperatorInput AskOperator();
};

// Drives a Robot with policy actions: keeps the gripper latch, runs the safety filter, turns the
// action into joint targets with the robot's kinematics (the twin's IK) and sends them.
class ActionClient {
 public:
  ActionClient(Robot& robot, const sim::ActionLimits& limits, const SafetyLimits& safety = {});

  // Sends one action computed from `observation` (its joint state is the IK's start). Returns
  // what the safety filter did. `now` is the robot-clock time used for staleness (default: the
  // observation's own stamp, i.e. fresh).
  FilterResult Act(const sim::Action& action, const Observation& observation,
                   std::optional<double> now = std::nullopt);
  // Forgets the gripper latch (after a reset the gripper is open).
  void ResetGripper() { gripper_ = {}; }

  const sim::Kinematics& kinematics() const { return kinematics_; }
  const sim::GripperState& gripper() const { return gripper_; }

 private:
  Robot& robot_;
  sim::ActionLimits limits_;
  SafetyFilter filter_;
  sim::Kinematics kinematics_;
  sim::GripperState gripper_;
};

// The robot description the client uses for a robot that calls itself `name`.
std::filesystem::path RobotDescriptionPath(const std::string& name);

}  // namespace twinforge::reality
