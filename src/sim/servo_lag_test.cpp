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

}  // namespace
}  // namespace twinforge::sim
