#include "sim/action.h"

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>

#include "core/error.h"

namespace twinforge::sim {

namespace {
constexpr const char* kDiscreteNames[kDiscreteActions] = {
    "+x",    "-x",     "+y",     "-y",   "+z",   "-z",   "+roll",
    "-roll", "+pitch", "-pitch", "+yaw", "-yaw", "open", "close"};
constexpr const char* kContinuousNames[kContinuousActionDim] = {"dx",     "dy",   "dz",     "droll",
                                                                "dpitch", "dyaw", "gripper"};
}  // namespace

const char* DiscreteActionName(int index) {
  return index >= 0 && index < kDiscreteActions ? kDiscreteNames[index] : "invalid";
}

nlohmann::json ToJson(const Action& a) {
  if (a.mode == ActionMode::kDiscrete) return DiscreteActionName(a.index);
  return a.value;
}

EeCommand DecodeAction(const Action& action, const ActionLimits& limits,
                       const GripperState& gripper) {
  EeCommand command;
  command.closure = gripper.closure;
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();
  Eigen::Vector3d rotation = Eigen::Vector3d::Zero();
  if (action.mode == ActionMode::kDiscrete) {
    const int i = action.index;
    if (i < 0 || i >= kDiscreteActions)
      throw core::NumericError("discrete action " + std::to_string(i) +
                               " is outside 0..13 (RialTo's 14 moves)");
    if (i < 6)
      translation[i / 2] = (i % 2 == 0 ? 1 : -1) * limits.translation;
    else if (i < 12)
      rotation[(i - 6) / 2] = ((i - 6) % 2 == 0 ? 1 : -1) * limits.rotation;
    else
      command.closure = i == 13 ? 1.0 : 0.0;
  } else {
    for (int k = 0; k < kContinuousActionDim; ++k)
      if (!std::isfinite(action.value[k]))
        throw core::NumericError(std::string("continuous action component '") +
                                 kContinuousNames[k] + "' is not finite");
    for (int k = 0; k < 3; ++k) {
      translation[k] = std::clamp(action.value[k], -limits.translation, limits.translation);
      rotation[k] = std::clamp(action.value[3 + k], -limits.rotation, limits.rotation);
    }
    command.closure = 0.5 * (std::clamp(action.value[6], -1.0, 1.0) + 1.0);
  }
  command.delta.translation = translation;
  command.delta.rotation = core::FromRollPitchYaw(rotation.x(), rotation.y(), rotation.z());
  return command;
}

JointTargets ActionToJointTargets(const Kinematics& kinematics, const ArmVector& q,
                                  const Action& action, const ActionLimits& limits,
                                  const GripperState& gripper, const IkOptions& ik) {
  if (!q.allFinite()) throw core::NumericError("measured joint positions are not finite");
  const EeCommand command = DecodeAction(action, limits, gripper);
  const core::Pose target = kinematics.EePose(q) * command.delta;
  JointTargets out;
  out.arm = kinematics.SolveIk(q, target, ik);
  out.closure = command.closure;
  const auto& spec = kinematics.spec();
  out.finger = spec.gripper_open + command.closure * (spec.gripper_closed - spec.gripper_open);
  return out;
}

}  // namespace twinforge::sim
