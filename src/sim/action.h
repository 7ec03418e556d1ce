// One action semantics for the twin, the proxy reality and a real robot.
//
// An action is an end-effector delta in the gripper frame plus a gripper command, either
//   continuous: (dx, dy, dz [m], droll, dpitch, dyaw [rad], gripper in [-1 open, +1 closed]),
//   clipped to the per-step limits, or
//   discrete: one of RialTo's 14 moves: 0..5 = +x -x +y -y +z -z (one translation step),
//   6..11 = +roll -roll +pitch -pitch +yaw -yaw (one rotation step), 12 = open, 13 = close
//   (the gripper latches until the opposite command).
// ActionToJointTargets is the only place an action becomes joint targets.
#pragma once

#include <array>
#include <nlohmann/json_fwd.hpp>
#include <string>

#include "core/se3.h"
#include "sim/robot.h"

namespace twinforge::sim {

enum class ActionMode { kDiscrete, kContinuous };

constexpr int kDiscreteActions = 14;
constexpr int kContinuousActionDim = 7;

struct ActionLimits {
  double translation = 0.03;  // m per step (discrete step size, continuous clip)
  double rotation = 0.2;      // rad per step
  template <class A>
  void Serialize(A& a) {
    a("translation", translation);
    a("rotation", rotation);
    a.Require(translation > 0, "translation", "a positive step in metres");
    a.Require(rotation > 0, "rotation", "a positive step in radians");
  }
};

struct Action {
  ActionMode mode = ActionMode::kDiscrete;
  int index = 0;                                     // discrete
  std::array<double, kContinuousActionDim> value{};  // continuous

  static Action Discrete(int index) { return {ActionMode::kDiscrete, index, {}}; }
  static Action Continuous(const std::array<double, kContinuousActionDim>& v) {
    return {ActionMode::kContinuous, 0, v};
  }
};

// Human-readable name of a discrete action ("+x", "close", ...).
const char* DiscreteActionName(int index);

// An action as a log shows it: a discrete one by name, a continuous one by its values.
nlohmann::json ToJson(const Action& a);

// The gripper's commanded closure, 0 = open .. 1 = closed, carried between steps (latching).
struct GripperState {
  double closure = 0.0;
};

// Pose delta (in the gripper frame) and gripper closure an action asks for.
struct EeCommand {
  core::Pose delta;
  double closure = 0.0;
};

// Decodes and validates an action. Throws NumericError for NaN/inf values or a discrete index
// outside 0..13, naming the offending component.
EeCommand DecodeAction(const Action& action, const ActionLimits& limits,
                       const GripperState& gripper);

struct JointTargets {
  ArmVector arm;
  double finger = 0.0;  // target of each finger joint
  double closure = 0.0;
};

// Turns an action into joint targets from the measured arm joint positions: decode, compose the
// delta with the current tool pose, solve IK, map closure to finger targets.
JointTargets ActionToJointTargets(const Kinematics& kinematics, const ArmVector& q,
                                  const Action& action, const ActionLimits& limits,
                                  const GripperState& gripper, const IkOptions& ik = {});

}  // namespace twinforge::sim
