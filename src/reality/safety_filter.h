// The client-side safety filter in front of every action sent to a robot: keeps the tool inside
// a workspace box, limits its speed, and stops on stale observations. Joint limits are kept by
// the IK every action goes through (sim/action.h).
#pragma once

#include <string>

#include "core/se3.h"
#include "sim/action.h"

namespace twinforge::reality {

struct SafetyLimits {
  Eigen::Vector3d workspace_min{-0.3, -0.6, 0.02};  // tool centre, robot base frame (m)
  Eigen::Vector3d workspace_max{0.9, 0.6, 1.0};
  double max_speed = 0.35;      // m/s of the tool centre
  double control_period = 0.1;  // s between actions
  double stale_after = 0.5;     // s: older observations stop the robot
};

struct FilterResult {
  sim::Action action;  // what to send: the input, clipped, or a stop
  bool modified = false;
  std::string reason;  // why it was modified ("" if not)
};

class SafetyFilter {
 public:
  explicit SafetyFilter(const SafetyLimits& limits) : limits_(limits) {}

  // Filters `action` given the current tool pose and the age of the observation it was computed
  // from. Out-of-box or too-fast moves become a continuous action that stops at the box/speed
  // limit (a discrete one becomes a stop); a stale observation becomes a stop. The gripper
  // command is kept unless the observation is stale.
  FilterResult Filter(const sim::Action& action, const core::Pose& tool,
                      const sim::ActionLimits& action_limits, const sim::GripperState& gripper,
                      double observation_age) const;

  const SafetyLimits& limits() const { return limits_; }

 private:
  SafetyLimits limits_;
};

}  // namespace twinforge::reality
