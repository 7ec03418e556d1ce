// A robot's low-level joint controller, as the twin models it (the settings, ServoLagSpec and
// ArmPhysicsScales, are part of a task's control spec in sim/task.h): how a real arm's servo
// differs from the twin's ideal position actuators. Commands take effect after a latency; the
// target the joints servo to moves toward the command by a fraction per physics step instead of
// jumping; the arm's gains, damping and dry friction are scaled from the robot model's.
// The proxy reality runs its hidden arm through this with its own values; system
// identification (real2sim/calibrate/robot_sysid.h) fits them to what a real arm did.
#pragma once

#include "sim/action.h"
#include "sim/env.h"

namespace twinforge::sim {

// Follows joint targets through the latency and the interpolation (Env::StepTargets' hook).
class ServoLag : public Env::SubstepHook {
 public:
  ServoLag(const ServoLagSpec& spec, const RobotIndex& robot, double timestep);
  // Starts from rest at the arm's current positions and the fingers' current command.
  void Reset(const mjData* d);
  // A new command; the previous one is followed until the latency has passed.
  void Command(const JointTargets& targets);
  void BeforeSubstep(const mjModel* m, mjData* d) override;

 private:
  ServoLagSpec spec_;
  RobotIndex robot_;
  double latency_substeps_;
  ArmVector applied_ = ArmVector::Zero(), active_ = ArmVector::Zero(),
            previous_ = ArmVector::Zero();
  double finger_ = 0, previous_finger_ = 0;
  int substep_ = 0;
};

// Multiplies `m`'s arm values (assumed nominal) by `scales`.
void ScaleArmPhysics(mjModel* m, const RobotIndex& robot, const ArmPhysicsScales& scales);
// Sets both fingers' force limit (N, symmetric): how hard the gripper closes.
void SetGripForce(mjModel* m, const RobotIndex& robot, double force);
// Both fingers' force limit in `m` (the larger of the two, N).
double GripForce(const mjModel* m, const RobotIndex& robot);

}  // namespace twinforge::sim
