// Sysid tests' fixture: a synthetic robot, the drawer task's own scene with other physics.
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "real2sim/calibrate/robot_sysid.h"

namespace twinforge::real2sim::testing {

// "The robot" is the drawer task's own scene with a lagging, softer arm whose joints are damped
// more, a weaker grip and a stiffer, heavier drawer; the twin is the same scene with the model's
// values.
struct Synthetic {
  sim::TaskSpec twin = sim::LoadTaskSpec("open_drawer");
  std::vector<PhysicalParameter> scene{
      {PhysicalParameter::Kind::kJointDamping, "drawer_slide", 0.05, 500},
      {PhysicalParameter::Kind::kJointFriction, "drawer_slide", 0.05, 200},
      {PhysicalParameter::Kind::kBodyMass, "drawer", 0.05, 50}};
  RobotPhysics truth;
  double twin_mass = TwinReplay(twin).NominalScene(scene)[2];
  Synthetic() {
    truth.servo = {0.3, 0.025};
    truth.arm = {0.75, 1.4, 1.5, 2.0};
    truth.grip_force = 45;  // the model's: 70 N
    truth.scene = {16, 5, 1.4 * twin_mass};
  }
  // The twin given the robot's controller and grip: no free moves needed.
  void KnowTheController() {
    twin.control.servo = truth.servo;
    twin.control.arm_scales = truth.arm;
    twin.control.grip_force = truth.grip_force;
  }
  RobotTrajectory Record(const std::string& name, std::vector<sim::JointTargets> targets) {
    RobotTrajectory t;
    t.name = name;
    t.targets = std::move(targets);
    t.q = TwinReplay(twin).Run(truth, scene, t.targets, &t.gripper_width);
    return t;
  }
};

}  // namespace twinforge::real2sim::testing
