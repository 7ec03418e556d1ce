// SAM-RL's residual policy on a base policy's actions: the base (RialTo's point-cloud student,
// discrete or continuous) proposes an action, the residual (an OffPolicyAgent in residual mode)
// reads the base's own features of the observation and that action, and adds a bounded delta.
//
// Actions meet as unit vectors in [-1, 1]^7: (dx, dy, dz) / translation limit, (droll, dpitch,
// dyaw) / rotation limit, gripper (-1 open .. +1 closed). A discrete move becomes the same
// displacement (one component at +-1) with the gripper's latched closure, so a zero delta sends
// the robot exactly the joint targets the base's move would.
#pragma once

#include "sim/action.h"

namespace twinforge::learn {

// `action` as a unit vector; `gripper` is the latch before the action (a discrete move keeps
// it unless it is open or close). Non-finite components throw core::NumericError.
void ToUnitAction(const sim::Action& action, const sim::ActionLimits& limits,
                  const sim::GripperState& gripper, float* unit);
// The continuous action a unit vector asks for (components clamped to [-1, 1]).
sim::Action FromUnitAction(const float* unit, const sim::ActionLimits& limits);

}  // namespace twinforge::learn
