#include "sim/trajectory_optimizer.h"

#include <gtest/gtest.h>

#include <cmath>

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

// The tip to a goal and turned to an orientation there (the planar arm turns about y): the turn
// costs as the cost says, and the optimized reach ends near both. Linearized every 5 steps only
// (IlqrOptions::linearize_every), the same reach still ends there.
TEST(TrajectoryOptimizer, IlqrTurnsASiteAndMayLinearizeEveryFewSteps) {
  ModelPtr m = LoadModelFromText(kArm);
  DataPtr start = MakeData(m.get());
  mj_forward(m.get(), start.get());
  const int tip = mj_name2id(m.get(), mjOBJ_SITE, "tip");
  // Shoulder 0.6 rad and elbow 0.9 rad put the tip here, turned -1.5 rad about y.
  const double q1 = 0.6, q2 = 0.9;
  const Eigen::Vector3d goal(0.3 * std::cos(q1) + 0.3 * std::cos(q1 + q2), 0,
                             -0.3 * std::sin(q1) - 0.3 * std::sin(q1 + q2));
  const Eigen::Quaterniond turned(Eigen::AngleAxisd(q1 + q2, Eigen::Vector3d::UnitY()));
  SiteReachCost cost(tip, goal);
  cost.Turn(tip, turned, 0.05);
  EXPECT_NEAR(cost.Angle(start.get()), q1 + q2, 1e-9);
  EXPECT_NEAR(cost.Terminal(m.get(), start.get(), nullptr),
              cost.terminal * ((cost.Distance(start.get()) * cost.Distance(start.get())) +
                               0.05 * (q1 + q2) * (q1 + q2)),
              1e-9);
  for (int every : {1, 5}) {
    IlqrOptions options;
    options.iterations = 100;
    options.tolerance = 1e-4;
    options.linearize_every = every;
    const IlqrResult r = OptimizeTrajectory(m.get(), start.get(), cost, 80, {}, options);
    EXPECT_LT(r.costs.back(), 0.05 * r.costs.front()) << "linearized every " << every;
    DataPtr d = MakeData(m.get());
    mj_copyData(d.get(), m.get(), start.get());
    for (int t = 0; t < 80; ++t) {
      for (int i = 0; i < m->nu; ++i) d->ctrl[i] = r.controls[t * m->nu + i];
      mj_step(m.get(), d.get());
    }
    mj_forward(m.get(), d.get());
    EXPECT_LT(cost.Distance(d.get()), 0.03) << "linearized every " << every;
    EXPECT_LT(cost.Angle(d.get()), 0.1) << "linearized every " << every;
  }
  IlqrOptions never;
  never.linearize_every = 0;
  EXPECT_THROW(OptimizeTrajectory(m.get(), start.get(), cost, 10, {}, never), core::Error);
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
