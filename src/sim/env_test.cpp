#include "sim/env.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>

#include "core/error.h"

namespace twinforge::sim {
namespace {

std::shared_ptr<const Task> DrawerTask() {
  static auto task = std::make_shared<const Task>(LoadTaskSpec("open_drawer"));
  return task;
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

}  // namespace
}  // namespace twinforge::sim
