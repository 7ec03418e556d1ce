#include "sim/servo_lag.h"

#include <algorithm>
#include <cmath>

namespace twinforge::sim {

ServoLag::ServoLag(const ServoLagSpec& spec, const RobotIndex& robot, double timestep)
    : spec_(spec),
      robot_(robot),
      // Rounded to a millionth of a step, so a latency of whole steps stays whole.
      latency_substeps_(std::round(spec.latency / timestep * 1e6) / 1e6) {}

void ServoLag::Reset(const mjData* d) {
  for (int k = 0; k < kArmDof; ++k) {
    applied_[k] = d->qpos[robot_.arm_qpos[k]];
    active_[k] = previous_[k] = applied_[k];
  }
  finger_ = previous_finger_ = d->ctrl[robot_.finger_actuator[0]];
  substep_ = 0;
}

void ServoLag::Command(const JointTargets& targets) {
  previous_ = active_;
  previous_finger_ = finger_;
  active_ = targets.arm;
  finger_ = targets.finger;
  substep_ = 0;
}

void ServoLag::BeforeSubstep(const mjModel*, mjData* d) {
  // The share of this step past the latency: a latency between two steps blends the old and the
  // new command for one step, so that what follows changes smoothly with the latency.
  const double started = std::clamp(substep_++ + 1 - latency_substeps_, 0.0, 1.0);
  const ArmVector goal = previous_ + started * (active_ - previous_);
  applied_ += spec_.interpolation * (goal - applied_);
  for (int k = 0; k < kArmDof; ++k) d->ctrl[robot_.arm_actuator[k]] = applied_[k];
  for (int k = 0; k < 2; ++k)
    d->ctrl[robot_.finger_actuator[k]] = started > 0.5 ? finger_ : previous_finger_;
}

void ScaleArmPhysics(mjModel* m, const RobotIndex& robot, const ArmPhysicsScales& scales) {
  for (int k = 0; k < kArmDof; ++k) {
    const int a = robot.arm_actuator[k];
    m->actuator_gainprm[mjNGAIN * a] *= scales.kp;
    m->actuator_biasprm[mjNBIAS * a + 1] *= scales.kp;
    m->actuator_biasprm[mjNBIAS * a + 2] *= scales.kd;
    m->dof_damping[robot.arm_dof[k]] *= scales.damping;
    m->dof_frictionloss[robot.arm_dof[k]] *= scales.frictionloss;
  }
}

void SetGripForce(mjModel* m, const RobotIndex& robot, double force) {
  for (int k = 0; k < 2; ++k) {
    const int a = robot.finger_actuator[k];
    m->actuator_forcerange[2 * a] = -force;
    m->actuator_forcerange[2 * a + 1] = force;
  }
}

double GripForce(const mjModel* m, const RobotIndex& robot) {
  double force = 0;
  for (int k = 0; k < 2; ++k)
    force = std::max(force, m->actuator_forcerange[2 * robot.finger_actuator[k] + 1]);
  return force;
}

}  // namespace twinforge::sim
