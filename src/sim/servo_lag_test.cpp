#include "sim/servo_lag.h"

#include <gtest/gtest.h>

#include <memory>

namespace twinforge::sim {
namespace {

// How far joint 0 gets toward a 0.2 rad step in one control period of a task with `servo`.
double StepResponse(const ServoLagSpec& servo) {
  TaskSpec spec = LoadTaskSpec("open_drawer");
  spec.control.servo = servo;
  Env env(std::make_shared<const Task>(spec));
  env.Reset(0, 0);
  const ArmVector start = env.ArmPositions();
  JointTargets targets;
  targets.arm = start;
  targets.arm[0] += 0.2;
  targets.finger = env.data()->ctrl[env.task().index().robot.finger_actuator[0]];
  env.StepTargets(targets);
  return env.ArmPositions()[0] - start[0];
}

TEST(ServoLag, ATaskServoMakesTheTwinsArmLag) {
  const double ideal = StepResponse({});
  const double lagging = StepResponse({0.2, 0.05});
  const double late = StepResponse({1.0, 0.09});
  EXPECT_GT(ideal, 0.15);
  EXPECT_LT(lagging, 0.9 * ideal);
  EXPECT_LT(late, lagging);  // 90 of the 100 ms waiting
}

TEST(ServoLag, ALatencyBetweenStepsBlendsSmoothly) {
  // 12.5 ms lies between the 10 and 15 ms steps; the response lies between theirs.
  const double ten = StepResponse({0.5, 0.010});
  const double between = StepResponse({0.5, 0.0125});
  const double fifteen = StepResponse({0.5, 0.015});
  EXPECT_LT(between, ten);
  EXPECT_GT(between, fifteen);
}

TEST(ServoLag, ArmScalesInTheTaskScaleTheCompiledGains) {
  TaskSpec spec = LoadTaskSpec("open_drawer");
  const Task nominal(spec);
  spec.control.arm_scales = {0.5, 2.0, 1.0, 3.0};
  const Task scaled(spec);
  const auto& r = nominal.index().robot;
  for (int k = 0; k < kArmDof; ++k) {
    const int a = r.arm_actuator[k], dof = r.arm_dof[k];
    ASSERT_GT(nominal.model()->dof_frictionloss[dof], 0);
    EXPECT_DOUBLE_EQ(scaled.model()->actuator_gainprm[mjNGAIN * a],
                     0.5 * nominal.model()->actuator_gainprm[mjNGAIN * a]);
    EXPECT_DOUBLE_EQ(scaled.model()->actuator_biasprm[mjNBIAS * a + 2],
                     2.0 * nominal.model()->actuator_biasprm[mjNBIAS * a + 2]);
    EXPECT_DOUBLE_EQ(scaled.model()->dof_frictionloss[dof],
                     3.0 * nominal.model()->dof_frictionloss[dof]);
  }
}

// The fingers' opening one control period after the gripper is commanded shut from open, with
// the task's grip force set to `force` (0: the robot model's own).
double WidthAfterClosing(double force, double* model_force) {
  TaskSpec spec = LoadTaskSpec("open_drawer");
  spec.control.grip_force = force;
  const auto task = std::make_shared<const Task>(spec);
  *model_force = GripForce(task->model(), task->index().robot);
  Env env(task);
  env.Reset(0, 0);
  JointTargets targets;
  targets.arm = env.ArmPositions();
  targets.finger = 0;
  env.StepTargets(targets);
  return 2 * env.FingerOpening();
}

TEST(ServoLag, AGripForceInTheTaskSetsTheFingersLimit) {
  double own = 0, weaker = 0;
  const double own_width = WidthAfterClosing(0, &own);
  const double weaker_width = WidthAfterClosing(45, &weaker);
  EXPECT_DOUBLE_EQ(own, 70);  // panda.xml
  EXPECT_DOUBLE_EQ(weaker, 45);
  // Closing on nothing against the fingers' damping, the weaker grip closes more slowly.
  EXPECT_LT(own_width, 0.06);
  EXPECT_GT(weaker_width, own_width + 0.01);
}

}  // namespace
}  // namespace twinforge::sim
