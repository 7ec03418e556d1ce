#include "sim/env.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>

#include "core/error.h"
#include "sim/expert.h"

namespace twinforge::sim {
namespace {

std::shared_ptr<const Task> DrawerTask() {
  static auto task = std::make_shared<const Task>(LoadTaskSpec("open_drawer"));
  return task;
}

// The twin posed from outside (SAM-RL's actor mirrors a robot and an estimate in it): the arm's
// tool and a placed object are where they were put.
TEST(Env, PoseRobotAndPlaceBodyPoseTheTwinWithoutSimulating) {
  Env env(std::make_shared<const Task>(LoadTaskSpec("peg_insertion")));
  env.Reset(3, 1);
  const ArmVector home = env.ArmPositions();
  ArmVector q = home;
  q[0] += 0.2;
  env.PoseRobot(q, 0.01, 1.0);
  EXPECT_NEAR((env.ArmPositions() - q).norm(), 0, 1e-12);
  EXPECT_NEAR(env.FingerOpening(), 0.01, 1e-12);
  EXPECT_EQ(env.gripper().closure, 1.0);
  const int peg = mj_name2id(env.model(), mjOBJ_BODY, "peg");
  const core::Pose there{Eigen::Vector3d(0.45, -0.1, 0.05), core::Yaw(0.3)};
  env.PlaceBody(peg, there);
  EXPECT_NEAR((env.BodyPose(peg).translation - there.translation).norm(), 0, 1e-12);
  EXPECT_NEAR(env.BodyPose(peg).rotation.angularDistance(there.rotation), 0, 1e-9);
  // A body welded to the world moves as randomization moves it (a griddle the actor saw
  // elsewhere), until the next reset.
  const int table = mj_name2id(env.model(), mjOBJ_BODY, "table");
  ASSERT_GE(table, 0);
  const core::Pose was = env.BodyPose(table);
  env.PlaceBody(table, there);
  EXPECT_NEAR((env.BodyPose(table).translation - there.translation).norm(), 0, 1e-12);
  EXPECT_NEAR(env.BodyPose(table).rotation.angularDistance(there.rotation), 0, 1e-9);
  env.Reset(3, 0);
  EXPECT_NEAR((env.BodyPose(table).translation - was.translation).norm(), 0, 1e-12);
  // A body on a joint is refused.
  Env drawer(DrawerTask());
  drawer.Reset(1, 0);
  const int moving = mj_name2id(drawer.model(), mjOBJ_BODY, "drawer");
  ASSERT_GE(moving, 0);
  try {
    drawer.PlaceBody(moving, there);
    FAIL() << "placed a body on a joint";
  } catch (const core::Error& e) {
    EXPECT_NE(std::string(e.what()).find("drawer"), std::string::npos) << e.what();
  }
}

// The dense return SAM-RL's Q may fit: 1 on success, else each predicate's share. A peg held
// upright above its hole scores the success distance over the tip's; tipped over, less again.
TEST(Env, SuccessClosenessIsOneOnSuccessAndFallsWithTheTipsDistance) {
  Env env(std::make_shared<const Task>(LoadTaskSpec("peg_insertion")));
  env.Reset(5, 1);
  const int peg = mj_name2id(env.model(), mjOBJ_BODY, "peg");
  const int tip = mj_name2id(env.model(), mjOBJ_SITE, "peg_tip");
  const int goal = mj_name2id(env.model(), mjOBJ_SITE, "hole_goal");
  ASSERT_GE(peg, 0);
  ASSERT_GE(tip, 0);
  ASSERT_GE(goal, 0);
  env.PlaceBody(peg, core::Pose{});
  const Eigen::Vector3d tip_in_peg = env.SitePose(tip).translation - env.BodyPose(peg).translation;
  const Eigen::Vector3d hole = env.SitePose(goal).translation;
  const auto tip_distance = [&] {
    return (env.SitePose(tip).translation - env.SitePose(goal).translation).norm();
  };
  // Upright, the tip 5 mm over the goal: success.
  env.PlaceBody(peg, core::Pose{hole + Eigen::Vector3d(0, 0, 0.005) - tip_in_peg, {}});
  ASSERT_TRUE(env.Success());
  EXPECT_EQ(env.SuccessCloseness(), 1.0);
  // Upright, 2 and 5 cm over it (a peg standing on the block, one lifted away): 0.5 and 0.2.
  double last = 1;
  for (const double height : {0.02, 0.05}) {
    env.PlaceBody(peg, core::Pose{hole + Eigen::Vector3d(0, 0, height) - tip_in_peg, {}});
    ASSERT_FALSE(env.Success());
    EXPECT_NEAR(env.SuccessCloseness(), 0.01 / height, 1e-9) << height;
    EXPECT_LT(env.SuccessCloseness(), last);
    last = env.SuccessCloseness();
  }
  // Tipped 60 deg about x: the axis's share, 0.5 / 0.98, times the distance's.
  const core::Quat tipped(Eigen::AngleAxisd(M_PI / 3, Eigen::Vector3d::UnitX()));
  env.PlaceBody(peg, core::Pose{hole + Eigen::Vector3d(0, 0, 0.02) - tipped * tip_in_peg, tipped});
  EXPECT_NEAR(tip_distance(), 0.02, 1e-9);
  EXPECT_NEAR(env.SuccessCloseness(), 0.5 * (0.5 / 0.98), 1e-6);
  // A drawer pulled half-way to its success opening, the fingers open: a half.
  Env drawer(DrawerTask());
  drawer.Reset(1, 0);
  const int slide = mj_name2id(drawer.model(), mjOBJ_JOINT, "drawer_slide");
  ASSERT_GE(slide, 0);
  ASSERT_GT(drawer.FingerOpening(), 0.03);
  drawer.mutable_data()->qpos[drawer.model()->jnt_qposadr[slide]] = 0.06;
  EXPECT_FALSE(drawer.Success());
  EXPECT_NEAR(drawer.SuccessCloseness(), 0.5, 1e-9);
}

// A top-down tool turning all the way round, wobbling a little: its proprioceptive quaternion
// moves smoothly (with the sign chosen by w >= 0 it flipped each time w crossed zero).
TEST(Env, TheToolsQuaternionDoesNotFlipAsATopDownToolTurns) {
  std::array<float, kProprioDim> last{}, now{};
  for (int k = 0; k <= 340; ++k) {
    const double yaw = (k - 170) * M_PI / 180;
    const core::Pose ee{Eigen::Vector3d(0.5, 0, 0.2),
                        core::Quat(Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ())) *
                            core::Quat(Eigen::AngleAxisd(M_PI + 0.05 * std::sin(3 * yaw),
                                                         Eigen::Vector3d::UnitX()))};
    MakeProprio(ee, 0.02, 0.02, now.data());
    if (k > 0) {
      double jump = 0;
      for (int i = 3; i < 7; ++i) jump += (now[i] - last[i]) * (now[i] - last[i]);
      EXPECT_LT(std::sqrt(jump), 0.05) << "yaw " << yaw;
    }
    last = now;
  }
}

TEST(Env, ArmTracksADiscreteMoveWithinOneControlPeriod) {
  Env env(DrawerTask());
  env.Reset(1, 0);
  for (int action : {4, 0, 2, 5, 1, 3, 4, 4, 8, 8, 9, 9, 6, 6, 7, 7, 10, 10, 11, 11}) {
    const core::Pose start = env.EePose();
    const core::Pose target = start * DecodeAction(Action::Discrete(action), {}, {}).delta;
    env.Step(Action::Discrete(action));
    const core::Pose after = env.EePose();
    EXPECT_LT((after.translation - target.translation).norm(), 0.006)
        << DiscreteActionName(action) << " start " << start.translation.transpose() << " target "
        << target.translation.transpose() << " got " << after.translation.transpose();
    EXPECT_LT(core::AngleBetween(after.rotation, target.rotation), 0.03)
        << DiscreteActionName(action);
  }
}

std::shared_ptr<const Task> DrawerWithPhysics(const PhysicsRandomization& physics) {
  TaskSpec spec = LoadTaskSpec("open_drawer");
  spec.randomization.physics = physics;
  return std::make_shared<const Task>(spec);
}

// Each episode draws its own scene physics within the ranges; the robot keeps its own; a level
// below `from_level` (and the next Reset) is the nominal model again.
TEST(Env, PhysicsRandomizationScalesTheSceneNotTheRobot) {
  PhysicsRandomization p;
  p.from_level = 1;
  p.damping = {1.5, 2.0};
  p.frictionloss = {0.5, 0.7};
  p.mass = {1.2, 1.4};
  p.grip_force = {0.4, 0.6};
  const auto task = DrawerWithPhysics(p);
  const mjModel* nominal = task->model();
  const int slide = task->index().state_joints.at(0);
  const int dof = nominal->jnt_dofadr[slide];
  const int drawer = nominal->jnt_bodyid[slide];
  const int finger = task->index().robot.finger_actuator[0];
  const int arm_dof = task->index().robot.arm_dof[0];
  Env env(task);
  std::vector<double> dampings;
  for (uint64_t seed = 1; seed <= 6; ++seed) {
    env.Reset(seed, 1);
    const mjModel* m = env.model();
    const double damping = m->dof_damping[dof] / nominal->dof_damping[dof];
    EXPECT_GE(damping, 1.5 - 1e-9);
    EXPECT_LE(damping, 2.0 + 1e-9);
    const double loss = m->dof_frictionloss[dof] / nominal->dof_frictionloss[dof];
    EXPECT_GE(loss, 0.5 - 1e-9);
    EXPECT_LE(loss, 0.7 + 1e-9);
    const double mass = m->body_mass[drawer] / nominal->body_mass[drawer];
    EXPECT_GE(mass, 1.2 - 1e-9);
    EXPECT_LE(mass, 1.4 + 1e-9);
    const double grip =
        m->actuator_forcerange[2 * finger + 1] / nominal->actuator_forcerange[2 * finger + 1];
    EXPECT_GE(grip, 0.4 - 1e-9);
    EXPECT_LE(grip, 0.6 + 1e-9);
    EXPECT_EQ(m->dof_damping[arm_dof], nominal->dof_damping[arm_dof]);
    dampings.push_back(damping);
  }
  EXPECT_GT(*std::max_element(dampings.begin(), dampings.end()) -
                *std::min_element(dampings.begin(), dampings.end()),
            0.1);
  env.Reset(1, 0);
  EXPECT_EQ(env.model()->dof_damping[dof], nominal->dof_damping[dof]);
  EXPECT_EQ(env.model()->actuator_forcerange[2 * finger + 1],
            nominal->actuator_forcerange[2 * finger + 1]);
}

// What the ranges do: the scripted expert's fingers straddle the drawer's bar, so the pull holds
// with a third of their force even on a drawer four times as stiff (20 of 20, measured); with a
// tenth of it on that drawer, the bar pushes the fingers apart and the expert mostly fails.
TEST(Env, AWeakGripOnAStiffDrawerSlipsAndTheExpertFails) {
  PhysicsRandomization p;
  p.from_level = 1;
  p.damping = p.frictionloss = {4, 4};
  p.grip_force = {0.1, 0.1};
  const auto nominal = EvaluateExpert(DrawerTask(), 20, 1, 7, 0.0, 2);
  const auto weak = EvaluateExpert(DrawerWithPhysics(p), 20, 1, 7, 0.0, 2);
  EXPECT_GE(nominal.successes, 18);
  EXPECT_LE(weak.successes, 10) << "nominal " << nominal.successes;
}

}  // namespace
}  // namespace twinforge::sim
