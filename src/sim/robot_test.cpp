#include "sim/robot.h"

#include <gtest/gtest.h>

#include "core/error.h"
#include "core/rng.h"
#include "sim/action.h"

namespace twinforge::sim {
namespace {

class RobotTest : public ::testing::Test {
 protected:
  RobotSpec spec_ = LoadRobotSpec(DefaultRobotPath());
  Kinematics kinematics_{spec_};
};

TEST_F(RobotTest, HomePosePointsTheGripperDownInFrontOfTheBase) {
  const core::Pose ee = kinematics_.EePose(kinematics_.home());
  EXPECT_GT(ee.translation.x(), 0.3);
  EXPECT_LT(std::abs(ee.translation.y()), 0.05);
  EXPECT_GT((ee.rotation * Eigen::Vector3d::UnitZ()).dot(-Eigen::Vector3d::UnitZ()), 0.95);
}

TEST_F(RobotTest, NoSelfContactsAcrossTheWorkspace) {
  ModelPtr model = LoadModel(spec_.mjcf_path());
  DataPtr data = MakeData(model.get());
  const RobotIndex index = RobotIndex::Resolve(model.get(), spec_);
  core::Rng rng(3);
  for (int trial = 0; trial < 200; ++trial) {
    // Home plus up to 0.5 rad per joint: the region the tasks work in.
    for (int k = 0; k < kArmDof; ++k)
      data->qpos[index.arm_qpos[k]] =
          std::clamp(spec_.home[k] + rng.Uniform(-0.5, 0.5), index.lower[k], index.upper[k]);
    mj_forward(model.get(), data.get());
    for (int c = 0; c < data->ncon; ++c)
      ADD_FAILURE() << "self-contact between "
                    << mj_id2name(model.get(), mjOBJ_GEOM, data->contact[c].geom1) << " and "
                    << mj_id2name(model.get(), mjOBJ_GEOM, data->contact[c].geom2);
    if (data->ncon) break;
  }
}

TEST_F(RobotTest, IkReachesCommandedPoses) {
  const ArmVector q0 = kinematics_.home();
  const core::Pose start = kinematics_.EePose(q0);
  const std::vector<core::Pose> deltas = {
      {{0.03, 0, 0}, core::Quat::Identity()},
      {{0, -0.03, 0}, core::Quat::Identity()},
      {{0, 0, 0.03}, core::Quat::Identity()},
      {{0, 0, 0}, core::FromRollPitchYaw(0.2, 0, 0)},
      {{0, 0, 0}, core::FromRollPitchYaw(0, -0.2, 0)},
      {{0, 0, 0}, core::FromRollPitchYaw(0, 0, 0.2)},
      {{0.02, 0.01, -0.02}, core::FromRollPitchYaw(0.1, 0.1, -0.1)}};
  for (const auto& delta : deltas) {
    const core::Pose target = start * delta;
    const ArmVector q = kinematics_.SolveIk(q0, target);
    const core::Pose reached = kinematics_.EePose(q);
    EXPECT_LT((reached.translation - target.translation).norm(), 1e-3)
        << delta.translation.transpose();
    EXPECT_LT(core::AngleBetween(reached.rotation, target.rotation), 5e-3);
  }
}

TEST_F(RobotTest, IkStaysWithinJointLimits) {
  const ArmVector q0 = kinematics_.home();
  core::Pose far = kinematics_.EePose(q0);
  far.translation += Eigen::Vector3d(2.0, 0, 0);  // unreachable
  const ArmVector q = kinematics_.SolveIk(q0, far);
  const auto& index = kinematics_.index();
  EXPECT_TRUE(q.allFinite());
  EXPECT_TRUE((q.array() >= index.lower.array()).all());
  EXPECT_TRUE((q.array() <= index.upper.array()).all());
}

TEST_F(RobotTest, DiscreteActionsMoveTheToolInItsOwnFrame) {
  const ArmVector q0 = kinematics_.home();
  const core::Pose start = kinematics_.EePose(q0);
  const JointTargets t = ActionToJointTargets(kinematics_, q0, Action::Discrete(4), {}, {});
  const core::Pose moved = kinematics_.EePose(t.arm);
  // +z is the approach direction: with the gripper pointing down the tool goes down 3 cm.
  const Eigen::Vector3d expected = start.rotation * Eigen::Vector3d(0, 0, 0.03);
  EXPECT_LT((moved.translation - start.translation - expected).norm(), 1e-3);
  EXPECT_NEAR(t.finger, spec_.gripper_open, 1e-12);
  const JointTargets closed = ActionToJointTargets(kinematics_, q0, Action::Discrete(13), {}, {});
  EXPECT_NEAR(closed.finger, spec_.gripper_closed, 1e-12);
  // The gripper latches: a motion keeps the last closure.
  const JointTargets still_closed =
      ActionToJointTargets(kinematics_, q0, Action::Discrete(0), {}, GripperState{1.0});
  EXPECT_NEAR(still_closed.closure, 1.0, 1e-12);
}

TEST_F(RobotTest, NanActionsAndBadIndicesAreRejectedByName) {
  const ArmVector q0 = kinematics_.home();
  auto nan = Action::Continuous({0, 0, std::nan(""), 0, 0, 0, 0});
  try {
    ActionToJointTargets(kinematics_, q0, nan, {}, {});
    FAIL();
  } catch (const core::NumericError& e) {
    EXPECT_NE(std::string(e.what()).find("'dz'"), std::string::npos) << e.what();
  }
  EXPECT_THROW(ActionToJointTargets(kinematics_, q0, Action::Discrete(14), {}, {}),
               core::NumericError);
}

TEST_F(RobotTest, ContinuousActionsAreClippedToTheStepLimits) {
  const EeCommand c =
      DecodeAction(Action::Continuous({1.0, 0, 0, 0, 0, 5.0, 1.0}), ActionLimits{}, {});
  EXPECT_NEAR(c.delta.translation.x(), 0.03, 1e-12);
  EXPECT_NEAR(core::LogMap(c.delta.rotation).z(), 0.2, 1e-9);
  EXPECT_NEAR(c.closure, 1.0, 1e-12);
}

}  // namespace
}  // namespace twinforge::sim
