#include "reality/safety_filter.h"

#include <gtest/gtest.h>

namespace twinforge::reality {
namespace {

const core::Pose kDownAt(const Eigen::Vector3d& p) {
  return {p, core::AxisAngle(Eigen::Vector3d::UnitX(), M_PI)};  // tool z points down
}

TEST(SafetyFilter, ClipsMovesThatLeaveTheWorkspaceBox) {
  SafetyFilter filter({});
  const core::Pose tool = kDownAt({0.5, 0.0, 0.03});
  // +z in the tool frame is down: 3 cm down from 3 cm would go below the 2 cm floor.
  const auto down = sim::Action::Continuous({0, 0, 0.03, 0, 0, 0, -1});
  const FilterResult r = filter.Filter(down, tool, {}, {}, 0.0);
  ASSERT_TRUE(r.modified);
  EXPECT_NE(r.reason.find("workspace"), std::string::npos);
  const Eigen::Vector3d after =
      tool.translation +
      tool.rotation * Eigen::Vector3d(r.action.value[0], r.action.value[1], r.action.value[2]);
  EXPECT_NEAR(after.z(), 0.02, 1e-9);
  // A discrete move out of the box becomes a stop that keeps the gripper as it was.
  const FilterResult d = filter.Filter(sim::Action::Discrete(4), tool, {}, {1.0}, 0.0);
  ASSERT_TRUE(d.modified);
  EXPECT_EQ(d.action.mode, sim::ActionMode::kContinuous);
  EXPECT_DOUBLE_EQ(d.action.value[2], 0.0);
  EXPECT_DOUBLE_EQ(d.action.value[6], 1.0);
}

TEST(SafetyFilter, PassesSafeMovesUnchanged) {
  SafetyFilter filter({});
  const FilterResult r =
      filter.Filter(sim::Action::Discrete(0), kDownAt({0.5, 0.0, 0.3}), {}, {}, 0.05);
  EXPECT_FALSE(r.modified);
  EXPECT_EQ(r.action.index, 0);
}

TEST(SafetyFilter, LimitsSpeedAndStopsOnStaleObservations) {
  SafetyLimits limits;
  limits.max_speed = 0.1;  // 1 cm per 0.1 s
  SafetyFilter filter(limits);
  const auto fast = sim::Action::Continuous({0.03, 0, 0, 0, 0, 0, 0});
  const FilterResult r = filter.Filter(fast, kDownAt({0.5, 0.0, 0.3}), {}, {}, 0.0);
  ASSERT_TRUE(r.modified);
  EXPECT_NEAR(Eigen::Vector3d(r.action.value[0], r.action.value[1], r.action.value[2]).norm(), 0.01,
              1e-9);
  const FilterResult stale = filter.Filter(fast, kDownAt({0.5, 0.0, 0.3}), {}, {}, 2.0);
  ASSERT_TRUE(stale.modified);
  EXPECT_NE(stale.reason.find("stale"), std::string::npos);
  EXPECT_DOUBLE_EQ(stale.action.value[0], 0.0);
}

}  // namespace
}  // namespace twinforge::reality
