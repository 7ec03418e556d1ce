#include "sim/trajectory_optimizer.h"

#include <gtest/gtest.h>

#include "core/error.h"
#include "sim/model.h"

namespace twinforge::sim {
namespace {

// A two-link planar arm under gravity with torque motors, the tip a site.
constexpr const char* kArm = R"(
<mujoco>
  <option timestep="0.01"/>
  <worldbody>
    <body name="upper">
      <joint name="shoulder" type="hinge" axis="0 1 0" damping="0.05"/>
      <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.03" mass="1"/>
      <body name="fore" pos="0.3 0 0">
        <joint name="elbow" type="hinge" axis="0 1 0" damping="0.05"/>
        <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.025" mass="0.5"/>
        <site name="tip" pos="0.3 0 0"/>
      </body>
    </body>
  </worldbody>
  <actuator>
    <motor joint="shoulder" ctrllimited="true" ctrlrange="-8 8"/>
    <motor joint="elbow" ctrllimited="true" ctrlrange="-8 8"/>
  </actuator>
</mujoco>)";

// From holding still (the arm falls) to the tip at a goal 40 cm away, at rest.
TEST(TrajectoryOptimizer, IlqrLowersTheCostOfAReach) {
  ModelPtr m = LoadModelFromText(kArm);
  DataPtr start = MakeData(m.get());
  mj_forward(m.get(), start.get());
  const Eigen::Vector3d goal(0.2, 0, 0.4);
  SiteReachCost cost(mj_name2id(m.get(), mjOBJ_SITE, "tip"), goal);
  const int horizon = 80;
  IlqrOptions options;
  options.iterations = 100;
  options.tolerance = 1e-4;
  const IlqrResult r = OptimizeTrajectory(m.get(), start.get(), cost, horizon, {}, options);
  ASSERT_GE(r.costs.size(), 2u);
  EXPECT_LT(r.costs.back(), 0.05 * r.costs.front())
      << r.costs.front() << " -> " << r.costs.back() << " in " << r.iterations;
  EXPECT_TRUE(r.converged) << r.iterations << " iterations";
  EXPECT_FALSE(r.stalled);
  EXPECT_NEAR(TrajectoryCostOf(m.get(), start.get(), cost, r.controls), r.costs.back(), 1e-9);

  // Replaying the controls brings the tip to the goal.
  DataPtr d = MakeData(m.get());
  mj_copyData(d.get(), m.get(), start.get());
  for (int t = 0; t < horizon; ++t) {
    for (int i = 0; i < m->nu; ++i) d->ctrl[i] = r.controls[t * m->nu + i];
    mj_step(m.get(), d.get());
  }
  mj_forward(m.get(), d.get());
  EXPECT_LT(cost.Distance(d.get()), 0.02);
  EXPECT_GT(cost.Distance(start.get()), 0.3);
}

TEST(TrajectoryOptimizer, BadControlsAreNamed) {
  ModelPtr m = LoadModelFromText(kArm);
  DataPtr start = MakeData(m.get());
  SiteReachCost cost(0, Eigen::Vector3d(0.2, 0, 0.4));
  EXPECT_THROW(OptimizeTrajectory(m.get(), start.get(), cost, 10, std::vector<double>(7)),
               core::Error);
  std::vector<double> nan(20, 0.0);
  nan[5] = NAN;
  EXPECT_THROW(OptimizeTrajectory(m.get(), start.get(), cost, 10, nan), core::NumericError);
}

}  // namespace
}  // namespace twinforge::sim
