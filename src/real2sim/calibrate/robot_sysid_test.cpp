#include "real2sim/calibrate/robot_sysid.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "real2sim/calibrate/test_support.h"

namespace twinforge::real2sim {
namespace {

using testing::Synthetic;

TEST(RobotSysid, FreeMovesStepEachJointOutAndBack) {
  Synthetic s;
  const auto targets = FreeArmTargets(s.twin, 0.15, 6);
  ASSERT_EQ(targets.size(), 8u * 12u);
  const sim::ArmVector rest = targets[6].arm;
  const double open = targets[0].finger;
  for (int k = 0; k < sim::kArmDof; ++k) {
    const sim::ArmVector out = targets[12 * k].arm - rest;
    EXPECT_NEAR(std::abs(out[k]), 0.15, 1e-12);
    EXPECT_NEAR(out.norm(), 0.15, 1e-12);  // that joint only
    EXPECT_TRUE(targets[12 * k + 11].arm.isApprox(rest));
    EXPECT_EQ(targets[12 * k].finger, open);
  }
  // Then the gripper, from open (the drawer's start) to shut and back, the arm at rest.
  EXPECT_GT(open, 0.03);
  for (int i = 0; i < 12; ++i) {
    EXPECT_TRUE(targets[84 + i].arm.isApprox(rest));
    EXPECT_EQ(targets[84 + i].finger, i < 6 ? 0.0 : open);
  }
}

TEST(RobotSysid, RecoversAKnownControllerAndDrawer) {
  Synthetic s;
  bool expert_success = false;
  const std::vector<RobotTrajectory> free{s.Record("free", FreeArmTargets(s.twin))};
  const std::vector<RobotTrajectory> runs{
      s.Record("half_speed", ExpertTargets(s.twin, 2, &expert_success)),
      s.Record("third_speed", ExpertTargets(s.twin, 3))};
  ASSERT_TRUE(expert_success);
  RobotSysidOptions options;
  const RobotSysidResult r = IdentifyRobotPhysics(s.twin, s.scene, free, runs, options);

  EXPECT_NEAR(r.start.scene[0], 10, 1e-9);  // the twin's own drawer_slide damping
  EXPECT_LT(r.free_error_after, 0.01 * r.free_error_before);
  EXPECT_LT(r.task_error_after, 0.1 * r.task_error_before);
  const auto& id = r.identified;
  // Noise-free and in the model's own form: every value comes back (to 1e-6 here; in practice
  // to machine precision).
  EXPECT_NEAR(id.servo.interpolation, 0.3, 1e-6);
  EXPECT_NEAR(id.servo.latency, 0.025, 1e-9);
  EXPECT_NEAR(id.arm.kp, 0.75, 1e-6);
  EXPECT_NEAR(id.arm.kd, 1.4, 1e-6);
  EXPECT_NEAR(id.arm.frictionloss, 2.0, 1e-6);
  // The joints' damping acts nearly as kd does; held at the twin's, the rest came back 2% off
  // and the drawer 30% (docs/calibrate.md).
  EXPECT_NEAR(id.arm.damping, 1.5, 1e-5);
  // The grip, from how fast the fingers closed on nothing (to 1e-14 N here). Held at the model's
  // 70 N, the proxy drawer's values came back 8-31% off or at their bounds (docs/calibrate.md,
  // stop 31).
  EXPECT_NEAR(r.start.grip_force, 70, 1e-9);
  EXPECT_TRUE(r.grip_identified);
  EXPECT_NEAR(id.grip_force, 45, 1e-6);
  EXPECT_LT(r.grip_error_after, 1e-6 * r.grip_error_before);
  // The drawer, its mass too, within 1% (the issue asks 15%). Before stop 57 the one run was the
  // expert re-planned at half speed: the damping and friction came back 3-6% off, and with the
  // mass fitted too (the controller given) 16% and 11% off. With the full-speed run added to
  // these, 50%, 24% and 25% off, all refused (docs/calibrate.md).
  EXPECT_TRUE(r.scene_explains_runs);
  ASSERT_EQ(r.scene_identified, std::vector<bool>({true, true, true}));
  EXPECT_NEAR(id.scene[0], 16, 0.01 * 16);
  EXPECT_NEAR(id.scene[1], 5, 0.01 * 5);
  EXPECT_NEAR(id.scene[2], 1.4 * s.twin_mass, 0.01 * 1.4 * s.twin_mass);
}

// A batch of replays is spread over threads, one twin each; the fit is the same whatever their
// number: the controller, the grip and the scene, the search included.
TEST(RobotSysid, TheFitIsTheSameWhateverTheThreadCount) {
  Synthetic s;
  // Short runs (held 2 periods; the expert at full speed): only the sameness is tested.
  const std::vector<RobotTrajectory> free{s.Record("free", FreeArmTargets(s.twin, 0.15, 2))};
  const std::vector<RobotTrajectory> runs{s.Record("full_speed", ExpertTargets(s.twin, 1))};
  RobotSysidOptions options;
  options.controller.iterations = 1;
  options.scene.iterations = 2;
  options.scene_search.iterations = 2;
  std::vector<RobotSysidResult> fits;
  for (int threads : {1, 2, 3}) {
    options.threads = threads;
    fits.push_back(IdentifyRobotPhysics(s.twin, s.scene, free, runs, options));
  }
  const RobotPhysics& one = fits[0].identified;
  EXPECT_LT(fits[0].free_error_after, 0.5 * fits[0].free_error_before);  // it fitted something
  for (size_t k = 1; k < fits.size(); ++k) {
    const RobotPhysics& other = fits[k].identified;
    EXPECT_EQ(other.servo.interpolation, one.servo.interpolation);
    EXPECT_EQ(other.servo.latency, one.servo.latency);
    EXPECT_EQ(other.arm.kp, one.arm.kp);
    EXPECT_EQ(other.arm.kd, one.arm.kd);
    EXPECT_EQ(other.arm.damping, one.arm.damping);
    EXPECT_EQ(other.arm.frictionloss, one.arm.frictionloss);
    EXPECT_EQ(other.grip_force, one.grip_force);
    EXPECT_EQ(fits[k].scene_fitted, fits[0].scene_fitted);
    EXPECT_EQ(fits[k].scene_curve, fits[0].scene_curve);
    EXPECT_EQ(fits[k].controller_curve, fits[0].controller_curve);
    EXPECT_EQ(fits[k].scene_controller_bound, fits[0].scene_controller_bound);
    EXPECT_EQ(fits[k].replays, fits[0].replays);
  }
}

// The task runs are one plan, each target sent once, twice or three times: re-planned at half
// speed the expert took another path, on which its fingers brushed the proxy drawer's bar.
TEST(RobotSysid, TheTaskRunsRepeatOnePlan) {
  Synthetic s;
  bool success = false;
  const auto once = ExpertTargets(s.twin, 1, &success), thrice = ExpertTargets(s.twin, 3);
  EXPECT_TRUE(success);
  ASSERT_GT(once.size(), 10u);
  ASSERT_EQ(thrice.size(), 3 * once.size());
  for (size_t i = 0; i < thrice.size(); ++i) {
    EXPECT_EQ(thrice[i].arm, once[i / 3].arm);
    EXPECT_EQ(thrice[i].finger, once[i / 3].finger);
  }
}

// The fit's error bars assume the model can fit the runs. Two runs of one drawer are fitted
// alone and agree; two runs of drawers unlike each other (a model that cannot fit both, as the
// twin's fixed grip cannot fit a real grip that slides along the bar) disagree, and nothing is
// identified, however tight the joint fit's error bars.
TEST(RobotSysid, AValueTheRunsDisagreeOnIsNotIdentified) {
  Synthetic s;
  s.KnowTheController();
  s.scene.pop_back();  // the damping and friction only
  auto runs_of = [&](const std::vector<double>& first, const std::vector<double>& second) {
    std::vector<RobotTrajectory> runs;
    bool success = false;
    s.truth.scene = first;
    runs.push_back(s.Record("third_speed", ExpertTargets(s.twin, 3, &success)));
    EXPECT_TRUE(success);
    s.truth.scene = second;
    runs.push_back(s.Record("half_speed", ExpertTargets(s.twin, 2, &success)));
    EXPECT_TRUE(success);
    RobotSysidOptions options;
    options.scene_search.iterations = 0;  // the split check is what is tested here
    return IdentifyRobotPhysics(s.twin, s.scene, {}, runs, options);
  };
  const RobotSysidResult same = runs_of({16, 5}, {16, 5});
  ASSERT_EQ(same.scene_per_run.size(), 2u);
  EXPECT_EQ(same.scene_identified, std::vector<bool>({true, true}));
  EXPECT_NEAR(same.identified.scene[0], 16, 0.1);
  EXPECT_NEAR(same.identified.scene[1], 5, 0.05);

  const RobotSysidResult unlike = runs_of({16, 5}, {6, 2});
  ASSERT_EQ(unlike.scene_per_run.size(), 2u);
  std::printf("unlike: joint fit %.3f (+-%.1f%%), %.3f (+-%.1f%%)\n", unlike.scene_fitted[0],
              100 * unlike.scene_relative_error[0], unlike.scene_fitted[1],
              100 * unlike.scene_relative_error[1]);
  // The joint fit's error bars alone would have taken both.
  EXPECT_LE(unlike.scene_relative_error[0], 0.15);
  EXPECT_LE(unlike.scene_relative_error[1], 0.15);
  EXPECT_GT(unlike.scene_per_run[0][0], 1.5 * unlike.scene_per_run[1][0]);  // 16 against 6
  EXPECT_EQ(unlike.scene_identified, std::vector<bool>({false, false}));
  EXPECT_EQ(unlike.identified.scene, unlike.start.scene);
}

// A model that lacks what the runs show cannot be trusted however tight its error bars: here the
// twin grips with 70 N, then 55, where "the robot" grips with 45 (no free moves to tell it).
// Before stop 57 such a fit took a friction 54% off. The search is off to keep the test short
// (with it, the 70 N fit leaves the run 0.013 deg off and is refused too).
TEST(RobotSysid, AFitThatLeavesTheRunsUnexplainedIsNotTaken) {
  for (double grip : {70.0, 55.0}) {
    Synthetic s;
    s.KnowTheController();
    s.twin.control.grip_force = grip;  // all but the grip
    const std::vector<RobotTrajectory> runs{s.Record("half_speed", ExpertTargets(s.twin, 2))};
    RobotSysidOptions options;
    options.scene_search.iterations = 0;
    const RobotSysidResult r = IdentifyRobotPhysics(s.twin, s.scene, {}, runs, options);
    const double rms_deg = std::sqrt(r.scene_curve.back()) * 180 / M_PI;
    std::printf(
        "grip %.0f N: the fit leaves the run %.3g deg RMS off, at damping %.2f, friction "
        "%.2f, mass %.2f kg\n",
        grip, rms_deg, r.scene_fitted[0], r.scene_fitted[1], r.scene_fitted[2]);
    // At 55 N the fit (3.5 / 2.3 / 6.7 kg against 16 / 5 / 4.1 kg) is closer than stop 57's 0.01
    // deg: the scanned drawer twin's calibrated fits were too (docs/calibrate.md, stop 58).
    if (grip == 55.0) EXPECT_LT(rms_deg, 0.01);
    EXPECT_FALSE(r.scene_explains_runs);
    EXPECT_EQ(r.scene_identified, std::vector<bool>({false, false, false}));
    EXPECT_EQ(r.identified.scene, r.start.scene);
  }
}

// A free object has no joint whose lag tells its physics, but an arm that holds it still sags
// under its weight. The peg task's expert is run until the peg is lifted clear of the table,
// then held; "the robot" has the proxy's heavier peg (80 g against the twin's 60). On the proxy
// the twin's arm went 0.04 deg off the robot's while the fingers closed on the scanned peg, 80
// times what the mass bends it by; the hold alone matched it (docs/calibrate.md, stop 65). Here
// the grasp's steps are put that far off by hand.
TEST(RobotSysid, RecoversTheMassOfWhatTheArmLiftsFromTheHold) {
  Synthetic s;
  s.twin = sim::LoadTaskSpec("peg_insertion");
  s.KnowTheController();
  s.scene = {{PhysicalParameter::Kind::kBodyMass, "peg", 0.005, 5}};
  s.truth.scene = {0.08};
  ASSERT_NEAR(TwinReplay(s.twin).NominalScene(s.scene)[0], 0.06, 1e-9);
  constexpr int kHold = 10;
  const auto half = LiftTargets(s.twin, 2, kHold);
  // Up to the lift (steps 0-3: over the peg, down, close, up), then held.
  ASSERT_GT(half.size(), 20u);
  EXPECT_EQ(half.back().arm, half[half.size() - kHold - 1].arm);
  std::vector<RobotTrajectory> runs{s.Record("half_speed", half),
                                    s.Record("third_speed", LiftTargets(s.twin, 3, kHold))};
  for (auto& run : runs) {
    EXPECT_TRUE(GripHeld(run)) << run.name;  // the peg in the hand
    run.fit_from = static_cast<long>(run.targets.size()) - kHold;
    for (long i = 0; i < run.fit_from; ++i)
      if (run.targets[i].finger == 0) run.q[i][1] += 0.04 * M_PI / 180;  // the grasp, off
  }
  RobotSysidOptions options;
  options.scene_search.iterations = 0;  // one value, near: Levenberg-Marquardt alone
  const RobotSysidResult r = IdentifyRobotPhysics(s.twin, s.scene, {}, runs, options);
  std::printf("the hold: %.3g deg RMS off with the twin's peg, %.3g after the fit; %.4f kg\n",
              std::sqrt(r.task_error_before) * 180 / M_PI,
              std::sqrt(r.task_error_after) * 180 / M_PI, r.scene_fitted[0]);
  EXPECT_TRUE(r.scene_explains_runs);
  ASSERT_EQ(r.scene_identified, std::vector<bool>({true}));
  EXPECT_NEAR(r.identified.scene[0], 0.08, 0.01 * 0.08);

  EXPECT_LT(r.scene_controller_bound[0], 1e-9);  // the controller given: no misfit

  // With the controller fitted to free moves, but roughly (one iteration), the hold is fitted as
  // well as the guard asks, yet the arm is not known well enough to weigh 80 g: the misfit
  // could move the mass by more than 15%. (On the proxy such a fit took the peg as 184 g.)
  const sim::TaskSpec rough = sim::LoadTaskSpec("peg_insertion");  // the model's controller
  RobotSysidOptions quick = options;
  quick.controller.iterations = 1;
  const RobotSysidResult guess =
      IdentifyRobotPhysics(rough, s.scene, {s.Record("free", FreeArmTargets(rough))}, runs, quick);
  std::printf("a rough controller: free moves %.3g deg RMS off; %.4f kg, bound %.0f%%\n",
              std::sqrt(guess.free_error_after) * 180 / M_PI, guess.scene_fitted[0],
              100 * guess.scene_controller_bound[0]);
  EXPECT_GT(guess.scene_controller_bound[0], 0.15);
  EXPECT_EQ(guess.scene_identified, std::vector<bool>({false}));

  // Fitted from the first step, the grasp's error is what the fit sees.
  for (auto& run : runs) run.fit_from = 0;
  const RobotSysidResult whole = IdentifyRobotPhysics(s.twin, s.scene, {}, runs, options);
  std::printf("the whole run: %.3g deg RMS off after the fit; %.4f kg\n",
              std::sqrt(whole.task_error_after) * 180 / M_PI, whole.scene_fitted[0]);
  EXPECT_FALSE(whole.scene_explains_runs);
  EXPECT_EQ(whole.identified.scene, whole.start.scene);

  // A script that never carries has nothing to lift.
  EXPECT_TRUE(LiftTargets(sim::LoadTaskSpec("open_drawer"), 2, kHold).empty());
}

TEST(RobotSysid, AGripIsHeldOnlyIfTheFingersStayApart) {
  RobotTrajectory t;
  for (double finger : {0.04, 0.0, 0.0, 0.04}) {
    sim::JointTargets target;
    target.finger = finger;
    t.targets.push_back(target);
  }
  t.gripper_width = {0.08, 0.02, 0.015, 0.06};
  EXPECT_TRUE(GripHeld(t));
  t.gripper_width[2] = 0.001;  // closed on nothing at the end of the pull
  EXPECT_FALSE(GripHeld(t));
  for (auto& target : t.targets) target.finger = 0.04;
  EXPECT_FALSE(GripHeld(t));  // never closed
}

}  // namespace
}  // namespace twinforge::real2sim
