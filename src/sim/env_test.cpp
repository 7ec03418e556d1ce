#include "sim/env.h"

#include <gtest/gtest.h>

#include "core/error.h"

namespace twinforge::sim {
namespace {

std::shared_ptr<const Task> DrawerTask() {
  static auto task = std::make_shared<const Task>(LoadTaskSpec("open_drawer"));
  return task;
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
