#include "reality/safety_filter.h"

#include <algorithm>

namespace twinforge::reality {

namespace {
// A continuous action that holds the tool still with the given gripper closure.
sim::Action Stop(double closure) {
  sim::Action a = sim::Action::Continuous({});
  a.value[6] = 2.0 * closure - 1.0;
  return a;
}
}  // namespace

FilterResult SafetyFilter::Filter(const sim::Action& action, const core::Pose& tool,
                                  const sim::ActionLimits& action_limits,
                                  const sim::GripperState& gripper, double observation_age) const {
  if (!(observation_age <= limits_.stale_after))  // also catches NaN ages
    return {Stop(gripper.closure), true, "observation is stale: stopping"};
  const sim::EeCommand command = sim::DecodeAction(action, action_limits, gripper);
  // Where the tool would go, in the base frame, and the nearest allowed place.
  const Eigen::Vector3d step = tool.rotation * command.delta.translation;
  const Eigen::Vector3d wanted = tool.translation + step;
  Eigen::Vector3d allowed = wanted.cwiseMax(limits_.workspace_min).cwiseMin(limits_.workspace_max);
  std::string reason;
  if ((allowed - wanted).norm() > 1e-9) reason = "target outside the workspace box";
  const double max_step = limits_.max_speed * limits_.control_period;
  Eigen::Vector3d allowed_step = allowed - tool.translation;
  if (allowed_step.norm() > max_step) {
    allowed_step *= max_step / allowed_step.norm();
    reason = reason.empty() ? "tool speed above the limit" : reason + "; speed limited";
  }
  if (reason.empty()) return {action, false, ""};
  if (action.mode == sim::ActionMode::kDiscrete) return {Stop(command.closure), true, reason};
  // Same rotation and gripper, translation clipped, back in the tool frame.
  sim::Action clipped = action;
  const Eigen::Vector3d local = tool.rotation.conjugate() * allowed_step;
  for (int k = 0; k < 3; ++k) clipped.value[k] = local[k];
  return {clipped, true, reason};
}

}  // namespace twinforge::reality
