// The scene's global search, on a drawer far from the twin's (slow: two fits of the drawer).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "real2sim/calibrate/robot_sysid.h"
#include "real2sim/calibrate/test_support.h"

namespace twinforge::real2sim {
namespace {

using testing::Synthetic;

// A drawer far from the twin's (4.5 times as damped, 3.5 times the friction, 2.5 times the mass):
// Levenberg-Marquardt alone stops in a dip on the way, a value 30% off or more (from both runs it
// took a damping 54% off as identified: docs/calibrate.md); the search first finds all three.
TEST(RobotSysid, TheSearchFindsADrawerFarFromTheTwins) {
  Synthetic s;
  s.KnowTheController();
  const std::vector<double> truth{45, 14, 2.5 * s.twin_mass};
  s.truth.scene = truth;
  const std::vector<RobotTrajectory> runs{s.Record("half_speed", ExpertTargets(s.twin, 2))};
  RobotSysidOptions options;
  const RobotSysidResult found = IdentifyRobotPhysics(s.twin, s.scene, {}, runs, options);
  EXPECT_EQ(found.scene_identified, std::vector<bool>({true, true, true}));
  for (size_t i = 0; i < truth.size(); ++i)
    EXPECT_NEAR(found.identified.scene[i], truth[i], 0.05 * truth[i]) << i;

  options.scene_search.iterations = 0;
  const RobotSysidResult stalled = IdentifyRobotPhysics(s.twin, s.scene, {}, runs, options);
  EXPECT_GT(stalled.task_error_after, 1e3 * found.task_error_after);
  double worst = 0;
  for (size_t i = 0; i < truth.size(); ++i)
    worst = std::max(worst, std::abs(stalled.scene_fitted[i] / truth[i] - 1));
  std::printf("searched %.2f %.2f %.2f, LM alone %.2f %.2f %.2f\n", found.scene_fitted[0],
              found.scene_fitted[1], found.scene_fitted[2], stalled.scene_fitted[0],
              stalled.scene_fitted[1], stalled.scene_fitted[2]);
  EXPECT_GT(worst, 0.3);
}

}  // namespace
}  // namespace twinforge::real2sim
