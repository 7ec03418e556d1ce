// SAM-RL's base actor on the proxy reality: object poses estimated from the robot's movable
// camera, the twin's expert acting on them. The hidden world is read only to grade.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>

#include "core/test_support.h"
#include "learn/torch_runtime.h"
#include "real2sim/build.h"
#include "reality/proxy_reality.h"
#include "reality/scan.h"
#include "samrl/active_camera.h"
#include "samrl/twin_actor.h"
#include "sim/camera.h"

namespace twinforge::samrl {
namespace {

// How far (m, in the table's plane) a site of the twin, with the objects where they were
// estimated, is from the same site of the hidden world.
double SiteError(const sim::Task& task, const std::vector<ObjectPose>& estimate,
                 const sim::Env& hidden, const char* site) {
  sim::Env twin(std::make_shared<const sim::Task>(task.spec()));
  twin.Reset(0, 0);
  for (const auto& e : estimate)
    twin.PlaceBody(mj_name2id(twin.model(), mjOBJ_BODY, e.body.c_str()), e.pose);
  const int a = mj_name2id(twin.model(), mjOBJ_SITE, site);
  const int b = mj_name2id(hidden.model(), mjOBJ_SITE, site);
  return (twin.SitePose(a).translation - hidden.SitePose(b).translation).head<2>().norm();
}

// The frame registered to the arm alone, as before stop 77.
PoseEstimateOptions ArmAlone() {
  PoseEstimateOptions o;
  o.register_tops = false;
  return o;
}

// The fits not polished point to plane, as before stop 88.
PoseEstimateOptions Unpolished() {
  PoseEstimateOptions o;
  o.polish = false;
  return o;
}

// Each start's ICP on every point near it, as before stop 89 (`start_points`): with 500 a start
// the block's fits change, and the trials some tests name no longer show what those tests check.
PoseEstimateOptions EveryPoint(PoseEstimateOptions o = {}) {
  o.start_points = 0;
  return o;
}

struct Scene {
  explicit Scene(const std::string& name)
      : spec(sim::LoadTaskSpec(name)),
        task(std::make_shared<const sim::Task>(spec)),
        proxy(reality::ResolveWorldDir(name)),
        camera(sim::MakeCamera(spec.camera)) {}
  // The objects estimated from one look at the scene reset with `seed` at `level`.
  std::vector<ObjectPose> Estimate(uint64_t seed, const Look& look,
                                   const PoseEstimateOptions& options = {}, int level = 1) {
    const reality::Observation o = proxy.Reset({seed, level});
    ObjectPoseEstimator estimator(task, spec.objects, options);
    std::vector<Eigen::Vector3d> points;
    for (const auto& frame : look({o, {}, ""})) {
      const auto p = estimator.Foreground(FramePoints(frame), o.q, o.gripper_width);
      points.insert(points.end(), p.begin(), p.end());
    }
    return estimator.Estimate(points);
  }
  // One 640x480 frame from where the task camera is said to be.
  Look TaskCameraLook() {
    return FixedLook(proxy, camera.pose, ScaleIntrinsics(camera.intrinsics, 8));
  }
  // The active look as eval makes it (with eval's --seed), on the twin as `geometry` draws it.
  Look EvalActiveLook(real2sim::TwinGeometry& geometry, uint64_t seed = 5000) {
    return ActiveLook(proxy, geometry, spec.objects, ObjectsMount(*task), LookSearchCamera(),
                      ScaleIntrinsics(camera.intrinsics, 8), LookSearch(), seed);
  }
  // `actor` on the proxy reset with `seed` at `level`, for at most `steps` actions; `before_act`
  // sees each observation and action.
  void Run(TwinActor& actor, uint64_t seed, int level, int steps, bool with_frames,
           const reality::BeforeAct& before_act = nullptr) {
    reality::ActionClient client(proxy, spec.control.limits);
    reality::Observation o = proxy.Reset({seed, level});
    client.ResetGripper();
    actor.Begin(seed);
    reality::RunOperator(proxy, actor, client, o, steps, with_frames, before_act);
  }
  // The task with two finger directions (+-fingers) on every step, as the peg's expert had until
  // stop 50.
  sim::TaskSpec TwoFingerDirections() const {
    sim::TaskSpec two = spec;
    for (auto& step : two.expert.steps) step.symmetry = 2;
    return two;
  }
  sim::TaskSpec spec;
  std::shared_ptr<const sim::Task> task;
  reality::ProxyReality proxy;
  sim::Camera camera;
};

// The hidden peg with the active look as eval makes it (with eval's --seed); eval's relook options
// for that look have the in-hand measure and the refine on.
struct HiddenPeg {
  // `seed_set`: eval's --seed, which seeds the active look and each trial.
  explicit HiddenPeg(uint64_t seed_set = 5000)
      : scene("peg_insertion_hidden"), geometry(scene.spec, 600), seeds(seed_set) {
    active = scene.EvalActiveLook(geometry, seeds);
  }
  static RelookOptions EvalRelook() {
    RelookOptions relook;
    relook.measure_held = relook.refine = true;
    return relook;
  }
  // How a trial on the proxy ended for the twin actor with the active look.
  struct Outcome {
    bool success = false;
    double hole_error = 0;  // m: the hole's site as believed at the end, from the hidden one
    int looks = 0, redone = 0;
  };
  // Eval's trial `trial` at `level`.
  Outcome RunTrial(int trial, int level, const RelookOptions& relook,
                   const PoseEstimateOptions& estimate = {}) {
    TwinActor actor(scene.task, scene.proxy, active, true, estimate, {}, relook);
    scene.Run(actor, core::MixSeed(seeds, 1000 * level + trial), level, scene.spec.horizon, true);
    return {scene.proxy.QuerySuccess() == reality::SuccessAnswer::kSuccess,
            SiteError(*scene.task, actor.estimates(), scene.proxy.hidden_env(), "hole_top"),
            actor.looks(), actor.redone_steps()};
  }
  Scene scene;
  real2sim::TwinGeometry geometry;
  uint64_t seeds;
  Look active;
};

// One 640x480 frame from where the task camera is said to be: both objects found to a few mm,
// once the frame is registered to the arm (the movable camera's pose is a few mm and mrad off;
// without the registration the estimates were 3-8 mm off).
TEST(PoseEstimate, TheObjectsOnTheProxyTableToAFewMillimetres) {
  Scene scene("peg_insertion");
  const Look look = scene.TaskCameraLook();
  for (uint64_t seed : {100, 101, 102}) {
    const auto estimate = scene.Estimate(seed, look);
    ASSERT_EQ(estimate.size(), 2u);
    for (const auto& e : estimate) EXPECT_TRUE(e.seen) << e.body << " seed " << seed;
    const sim::Env& hidden = scene.proxy.hidden_env();
    EXPECT_LT(SiteError(*scene.task, estimate, hidden, "peg_grasp"), 0.003) << "seed " << seed;
    EXPECT_LT(SiteError(*scene.task, estimate, hidden, "hole_top"), 0.004) << "seed " << seed;
  }
}

// Level 2 puts one to four boxes, 3 to 9 cm a side, on the table. Fitted to the lower part of a
// taller box, the block (or the peg) explained more points than where it really stands; points
// over an object's outline now count against a fit there. These are eval's level-2 trials 0-2
// (seeds 5000), where the hole was believed 14-17 cm off, or the peg 10 cm, before.
TEST(PoseEstimate, NotFittedToATallerBoxOfTheClutter) {
  learn::PinMathThreads(1);
  Scene scene("peg_insertion");
  const Look look = scene.TaskCameraLook();
  for (uint64_t trial : {0, 1, 2}) {
    const auto estimate = scene.Estimate(core::MixSeed(5000, 2000 + trial), look, {}, 2);
    const sim::Env& hidden = scene.proxy.hidden_env();
    EXPECT_LT(SiteError(*scene.task, estimate, hidden, "peg_grasp"), 0.003) << "trial " << trial;
    EXPECT_LT(SiteError(*scene.task, estimate, hidden, "hole_top"), 0.004) << "trial " << trial;
  }
}

// The proxy's hole block is dark rubber, whose depth returns the sensor loses more than half
// of: a brighter clutter box of its size gives a fit up to three times the points to explain.
// The clutter box has no hole, and its top shows where the block's would be; a point where a fit
// leaves free space now weighs ten explained ones. These are eval's level-2 trials
// 3, 5 and 13 of seeds 5000, where the block was believed 14-17 cm off, and trial 19 of seeds
// 7000, where the peg was believed 19 cm off, fitted to the clutter before.
TEST(PoseEstimate, NotFittedToABoxOfTheClutterThatReturnsMorePoints) {
  learn::PinMathThreads(1);
  Scene scene("peg_insertion");
  const Look look = scene.TaskCameraLook();
  for (const auto& [seeds, trial] :
       std::vector<std::pair<uint64_t, uint64_t>>{{5000, 3}, {5000, 5}, {5000, 13}, {7000, 19}}) {
    const auto estimate = scene.Estimate(core::MixSeed(seeds, 2000 + trial), look, {}, 2);
    const sim::Env& hidden = scene.proxy.hidden_env();
    EXPECT_LT(SiteError(*scene.task, estimate, hidden, "peg_grasp"), 0.003)
        << "seeds " << seeds << " trial " << trial;
    EXPECT_LT(SiteError(*scene.task, estimate, hidden, "hole_top"), 0.004)
        << "seeds " << seeds << " trial " << trial;
  }
}

// The hidden peg's level-2 trial 5 (seeds 5000), first look, from where eval's active look takes
// it: a clutter box 17 cm from the block's place in the twin explained 3324 points, the block
// 844. The fit began at a start within the search radius (15 cm) and slid out to the box; the
// block was believed there at every look and the trial failed. Fits that end beyond the radius
// are not taken.
TEST(PoseEstimate, NotFittedToABoxBeyondTheSearchRadius) {
  learn::PinMathThreads(1);
  Scene scene("peg_insertion_hidden");
  real2sim::TwinGeometry geometry(scene.spec, 600);
  const auto estimate =
      scene.Estimate(core::MixSeed(5000, 2000 + 5), scene.EvalActiveLook(geometry), {}, 2);
  const sim::Env& hidden = scene.proxy.hidden_env();
  for (const auto& e : estimate) EXPECT_TRUE(e.seen) << e.body;
  EXPECT_LT(SiteError(*scene.task, estimate, hidden, "peg_grasp"), 0.003);
  EXPECT_LT(SiteError(*scene.task, estimate, hidden, "hole_top"), 0.003);
}

// The proxy's hole block is dark: about 300 returns. The ICP's starts stopped 2-4 mm either side
// of it across the camera (world y), their scores (points within 3 mm) 1-2 apart, so which side a
// frame's fit took was chance. Settled where the points' capped squared distances are least, each
// of four frames of eval's level-1 trial 3 (seeds 5000) puts it within 1.5 mm.
TEST(PoseEstimate, SettledOnTheDarkBlockWhereItsPointsAreNearest) {
  learn::PinMathThreads(1);
  Scene scene("peg_insertion");
  const Look look = scene.TaskCameraLook();
  const reality::Observation o = scene.proxy.Reset({core::MixSeed(5000, 1000 + 3), 1});
  PoseEstimateOptions unsettled;
  unsettled.settle = 0;
  unsettled.polish = false;  // which takes two of the four within 2 mm
  ObjectPoseEstimator settling(scene.task, scene.spec.objects);
  ObjectPoseEstimator not_settling(scene.task, scene.spec.objects, unsettled);
  int off = 0;
  for (int frame = 0; frame < 4; ++frame) {
    const auto frames = look({o, {}, ""});
    ASSERT_EQ(frames.size(), 1u);
    const auto points = settling.Foreground(FramePoints(frames[0]), o.q, o.gripper_width);
    const sim::Env& hidden = scene.proxy.hidden_env();
    EXPECT_LT(SiteError(*scene.task, settling.Estimate(points), hidden, "hole_top"), 0.0015)
        << "frame " << frame;
    off += SiteError(*scene.task, not_settling.Estimate(points), hidden, "hole_top") > 0.002;
  }
  EXPECT_GE(off, 3) << "of 4 frames, fits neither polished nor settled more than 2 mm off";
}

// The starts of a fit run on a pool; the fit is the same, bit for bit, on one thread or three
// (the spatula's scene: three objects, the griddle's many starts; one frame for both).
TEST(PoseEstimate, TheSameWhateverTheThreadCount) {
  // As the program does: Open3D's ICP (the frame's registration) sums over OpenMP threads in
  // whatever order they finish, a last-bit difference that the fit then carries.
  learn::PinMathThreads(1);
  Scene scene("spatula_flipping");
  const reality::Observation o = scene.proxy.Reset({300, 1});
  const auto frames = FixedLook(scene.proxy, scene.camera.pose,
                                ScaleIntrinsics(scene.camera.intrinsics, 4))({o, {}, ""});
  ASSERT_EQ(frames.size(), 1u);
  const auto estimate = [&](int threads) {
    ObjectPoseEstimator estimator(scene.task, scene.spec.objects, {}, threads);
    return estimator.Estimate(estimator.Foreground(FramePoints(frames[0]), o.q, o.gripper_width));
  };
  const auto one = estimate(1), three = estimate(3);
  ASSERT_EQ(one.size(), three.size());
  for (std::size_t i = 0; i < one.size(); ++i) {
    EXPECT_TRUE(one[i].seen) << one[i].body;
    EXPECT_EQ(one[i].pose.translation, three[i].pose.translation) << one[i].body;
    EXPECT_EQ(one[i].pose.rotation.coeffs(), three[i].pose.rotation.coeffs()) << one[i].body;
    EXPECT_EQ(one[i].inliers, three[i].inliers) << one[i].body;
    EXPECT_EQ(one[i].outliers, three[i].outliers) << one[i].body;
  }
}

// From a view on the panel's side that shows little of the arm (train samrl's episode 2, seeds
// 7000: the twin's own frame, which needs no registration), registering the frame to the arm slid
// it 75 mm and 26 deg. 81% of the frame stayed in the foreground, the fits took 90 s, and the
// block was fitted 14 cm off. A registration that leaves fewer points on the twin's fixed geometry
// than the frame as it came is not used. Since stop 77 the table's top holds the frame too: it
// does not slide (the arm alone is checked here, as the safeguard's case).
TEST(PoseEstimate, ARegistrationThatSlidOffTheArmIsNotUsed) {
  learn::PinMathThreads(1);
  const sim::TaskSpec spec = sim::LoadTaskSpec("peg_insertion_occluded");
  const auto task = std::make_shared<const sim::Task>(spec);
  const auto twin =
      reality::ProxyReality::SimulatedTwin(spec, reality::ProxyReality::Sensor::kIdeal);
  const reality::Observation o = twin->Reset({17661929549578578993ull, 1});
  const sim::Camera camera = sim::MakeCamera(spec.camera);
  const reality::RgbdFrame frame = twin->Capture(
      {OrbitPose(ObjectsMount(*task), -0.1708, 1.0001), ScaleIntrinsics(camera.intrinsics, 8)});
  ObjectPoseEstimator estimator(task, spec.objects, ArmAlone());
  core::Pose correction;
  const auto points = estimator.Foreground(FramePoints(frame), o.q, o.gripper_width, &correction);
  EXPECT_EQ(correction.translation.norm(), 0.0);
  const nlohmann::json truth = twin->GraderState().at("objects");
  // The twin's own frame needs no registration: with the table it moves the objects' points
  // under a millimetre.
  ObjectPoseEstimator with_table(task, spec.objects);
  core::Pose held;
  with_table.Foreground(FramePoints(frame), o.q, o.gripper_width, &held);
  for (const auto& [body, at] : truth.items()) {
    const auto t = at.get<std::array<double, 3>>();
    const Eigen::Vector3d p(t[0], t[1], t[2]);
    EXPECT_LT((held * p - p).norm(), 0.001) << body;
  }
  EXPECT_LT(points.size(), 10000u) << "of " << frame.depth.size();
  for (const ObjectPose& found : estimator.Estimate(points)) {
    const auto t = truth.at(found.body).get<std::array<double, 3>>();
    EXPECT_LT((found.pose.translation.head<2>() - Eigen::Vector2d(t[0], t[1])).norm(), 0.005)
        << found.body;
  }
}

// The hidden peg's first look (eval's level-1 trial 0, seeds 5000, from where the active look took
// it) shows little of the arm, at rest behind the objects. Registered to the arm alone, the frame
// turned about it (0.38 deg in the first frame), which left most of the table off the twin's, so
// the registration was not used and the block was fitted with all of the movable camera's error
// (2 mm and 3 mrad a frame on the proxy): 1.5-4.6 mm off. The table's top holds the frame's height
// and tilt, the arm the rest: three frames (each with its own error) put the hole within 1.5 mm
// (0.3-0.7 mm).
TEST(PoseEstimate, TheTableHoldsTheTiltTheArmAloneLeavesFree) {
  learn::PinMathThreads(1);
  Scene scene("peg_insertion_hidden");
  const reality::Observation o = scene.proxy.Reset({core::MixSeed(5000, 1000), 1});
  ObjectPoseEstimator with_table(scene.task, scene.spec.objects);
  ObjectPoseEstimator without(scene.task, scene.spec.objects, ArmAlone());
  const sim::Env& hidden = scene.proxy.hidden_env();
  double worst_with = 0, sum_without = 0;
  for (int frame = 0; frame < 3; ++frame) {
    const reality::RgbdFrame f =
        scene.proxy.Capture({OrbitPose(ObjectsMount(*scene.task), -0.78, 1.00),
                             ScaleIntrinsics(scene.camera.intrinsics, 8)});
    const auto hole_off = [&](ObjectPoseEstimator& estimator) {
      return SiteError(
          *scene.task,
          estimator.Estimate(estimator.Foreground(FramePoints(f), o.q, o.gripper_width)), hidden,
          "hole_top");
    };
    const double with = hole_off(with_table), alone = hole_off(without);
    std::printf(
        "frame %d: the hole %.1f mm off registered with the table, %.1f mm with the arm alone\n",
        frame, 1e3 * with, 1e3 * alone);
    worst_with = std::max(worst_with, with);
    sum_without += alone;
  }
  EXPECT_LT(worst_with, 0.0015);
  EXPECT_GT(sum_without / 3, 0.0025);
}

// How far (m) the registration of a frame of the hidden peg (scene `s` at level 1, the movable
// camera at `azimuth`, `elevation` about the objects) leaves the block from where it is, with
// each of two estimators; and as the frame came.
struct BlockOff {
  double came, first, second;
};
BlockOff BlockAfterRegistration(Scene& scene, int s, double azimuth, double elevation,
                                ObjectPoseEstimator& first, ObjectPoseEstimator& second) {
  const Eigen::Vector3d block(0.56, 0.10, 0.04);  // robot frame, m
  const reality::Observation o = scene.proxy.Reset({core::MixSeed(5000, 1000 + s), 1});
  const core::Pose asked = OrbitPose(ObjectsMount(*scene.task), azimuth, elevation);
  const reality::RgbdFrame f =
      scene.proxy.Capture({asked, ScaleIntrinsics(scene.camera.intrinsics, 8)});
  // Where the frame shows the block, and where the registration then puts it.
  const core::Pose error = asked * scene.proxy.last_capture_error() * asked.Inverse();
  const Eigen::Vector3d shown = error.Inverse() * block;
  const auto off = [&](ObjectPoseEstimator& estimator) {
    core::Pose moved;
    estimator.Foreground(FramePoints(f), o.q, o.gripper_width, &moved);
    return (moved * shown - block).norm();
  };
  return {(shown - block).norm(), off(first), off(second)};
}

PoseEstimateOptions Open3dIcp() {
  PoseEstimateOptions o;
  o.register_min_hold = 0;
  return o;
}

// Seen from the side, the arm (resting behind the objects) holds some directions of the frame's
// motion by a handful of pairs, and Open3D's ICP slid the frame along them, 5-7 mm at the block.
// The registration now moves the frame only along the directions its pairs hold (stop 78); along
// the others the frame keeps the camera's own error (2-5 mm here).
TEST(PoseEstimate, ASideViewOfTheArmDoesNotSlideTheFrame) {
  learn::PinMathThreads(1);
  Scene scene("peg_insertion_hidden");
  ObjectPoseEstimator held(scene.task, scene.spec.objects),
      slid(scene.task, scene.spec.objects, Open3dIcp());
  double came_sum = 0, held_sum = 0, held_worst = 0, slid_sum = 0, slid_worst = 0;
  int frames = 0;
  for (int s = 0; s < 4; ++s)
    for (const auto& [azimuth, elevation] : {std::pair{0.8, 0.85}, std::pair{1.6, 1.15}}) {
      const auto [came, h, d] = BlockAfterRegistration(scene, s, azimuth, elevation, held, slid);
      came_sum += came;
      std::printf(
          "scene %d, view (%.2f, %.2f): the block %.1f mm off as it came, %.1f held, "
          "%.1f with Open3D's ICP\n",
          s, azimuth, elevation, 1e3 * came, 1e3 * h, 1e3 * d);
      held_sum += h;
      slid_sum += d;
      held_worst = std::max(held_worst, h);
      slid_worst = std::max(slid_worst, d);
      ++frames;
    }
  EXPECT_LT(held_worst, 0.004);
  EXPECT_LT(held_sum / frames, 0.0026);
  // Registered, not left as they came (3.1 mm on average).
  EXPECT_LT(held_sum, 0.8 * came_sum);
  EXPECT_GT(slid_worst, 0.006);
  EXPECT_GT(slid_sum / frames, 0.0035);
}

// From the active look's first view the arm holds every direction by dozens of pairs or more,
// and the registration agrees with Open3D's to 0.05 mm at the block. Leaving out directions held
// by fewer than 100 pairs (a first try) left these frames 1.2-2.2 mm off where Open3D's ICP left
// 0.4-0.5.
TEST(PoseEstimate, TheFirstLooksViewLeavesNothingOut) {
  learn::PinMathThreads(1);
  Scene scene("peg_insertion_hidden");
  ObjectPoseEstimator held(scene.task, scene.spec.objects),
      open3d(scene.task, scene.spec.objects, Open3dIcp());
  for (const int s : {2, 6}) {
    const auto [came, h, o] = BlockAfterRegistration(scene, s, -0.78, 1.00, held, open3d);
    std::printf("scene %d: the block %.2f mm off as it came, %.2f held, %.2f with Open3D's ICP\n",
                s, 1e3 * came, 1e3 * h, 1e3 * o);
    EXPECT_LT(h, 0.0006);
    EXPECT_NEAR(h, o, 5e-5);
  }
}

// The twin's expert on the estimate puts the peg in the proxy's hole.
TEST(TwinActorOnReality, InsertsThePegWhereTheEstimateSaysTheHoleIs) {
  learn::PinMathThreads(1);
  Scene scene("peg_insertion");
  TwinActor actor(scene.task, scene.proxy, scene.TaskCameraLook(), true);
  reality::ActionClient client(scene.proxy, scene.spec.control.limits);
  int successes = 0;
  const int trials = 6;
  for (int i = 0; i < trials; ++i) {
    reality::Observation o = scene.proxy.Reset({uint64_t(100 + i), 1});
    client.ResetGripper();
    actor.Begin(i);
    reality::RunOperator(scene.proxy, actor, client, o, scene.spec.horizon, false);
    successes += scene.proxy.QuerySuccess() == reality::SuccessAnswer::kSuccess;
    ASSERT_EQ(actor.estimates().size(), 2u);
  }
  EXPECT_GE(successes, 3) << successes << " of " << trials;
}

// How far a body's site is from the grasp site on it, in the body's frame.
double Reach(const sim::Env& env, const char* body, const char* grasp, const char* tip) {
  const mjModel* m = env.model();
  const int a = mj_name2id(m, mjOBJ_SITE, grasp), b = mj_name2id(m, mjOBJ_SITE, tip);
  EXPECT_EQ(m->site_bodyid[a], mj_name2id(m, mjOBJ_BODY, body));
  return (Eigen::Map<const Eigen::Vector3d>(m->site_pos + 3 * a) -
          Eigen::Map<const Eigen::Vector3d>(m->site_pos + 3 * b))
      .norm();
}

// The fingers close on the spatula's handle, 7 cm from the spatula's frame (its middle): the twin
// carries the spatula up with the tool as the proxy's gripper lifts it. It used to take only an
// object whose frame was within 5 cm, so the twin's spatula stayed on the table and the expert
// chased its blade across the room. Looking at the spatula in the hand once it is lifted
// (--measure-reach), the twin's blade tip is moved to where the proxy's blade ends: the drawing's
// is 1 cm short.
TEST(TwinActorOnReality, CarriesTheSpatulaAndMeasuresHowFarItsBladeReaches) {
  learn::PinMathThreads(1);
  Scene scene("spatula_flipping");
  RelookOptions relook;
  relook.measure_reach = true;
  relook.max_looks = 1;  // the scene once, then the spatula in the hand (not counted)
  TwinActor actor(scene.task, scene.proxy, scene.TaskCameraLook(), true, {}, {}, relook);
  // Grasped by step 22; lifted toward the griddle, and looked at, by step 60.
  scene.Run(actor, 5000, 1, 60, false);
  const sim::Env& hidden = scene.proxy.hidden_env();
  const int real = mj_name2id(hidden.model(), mjOBJ_BODY, "spatula");
  const int twin = mj_name2id(actor.twin().model(), mjOBJ_BODY, "spatula");
  const Eigen::Vector3d real_at = hidden.BodyPose(real).translation;
  // It rests at 4.6 cm; by step 60 the blade is coming down in front of the pancake.
  ASSERT_GT(real_at.z(), 0.06) << "the proxy's gripper is not holding the spatula up";
  EXPECT_LT((actor.twin().BodyPose(twin).translation - real_at).norm(), 0.02)
      << "the twin's spatula is not where the proxy's is";
  EXPECT_EQ(actor.looks(), 1);
  const double real_reach = Reach(hidden, "spatula", "spatula_grasp", "blade_tip");
  sim::Env drawn(scene.task);
  ASSERT_GT(std::abs(Reach(drawn, "spatula", "spatula_grasp", "blade_tip") - real_reach), 0.008);
  EXPECT_NEAR(Reach(actor.twin(), "spatula", "spatula_grasp", "blade_tip"), real_reach, 0.004);
}

// A twin built, under `dir`, from a scan of the proxy spatula as `twinforge scan capture` and
// `twin build --task spatula_flipping` make it.
std::shared_ptr<const sim::Task> ScannedSpatula(reality::ProxyReality& proxy,
                                                const std::filesystem::path& dir) {
  const sim::TaskSpec spec = sim::LoadTaskSpec("spatula_flipping");
  const reality::ScanOptions scan;
  reality::CaptureScan(proxy, reality::ScanPath(spec, scan), reality::ScanIntrinsics(scan),
                       dir / "scan");
  real2sim::BuildOptions options;
  options.task = spec;
  real2sim::BuildTwin(dir / "scan", dir / "twin", options);
  return std::make_shared<const sim::Task>(sim::LoadTaskSpec((dir / "twin/task.yaml").string()));
}

// A twin built from a scan of the proxy spatula: its pancake, carved out of the griddle's segment,
// is round, and a fit cannot see its turn (stop 86: the fits' turns swung its near edge round
// it, and the blade came at the pancake from the side in 17 trials of 17). It is turned with its
// griddle: with the griddle found where a level-1 scene turned it (0.2 rad or more) and the
// pancake fitted 2 rad round, the near edge the blade goes under faces the way the proxy's does.
TEST(TwinActorOnReality, TheScannedPancakeIsRoundAndItsNearEdgeTurnsWithItsGriddle) {
  reality::ProxyReality proxy(reality::ResolveWorldDir("spatula_flipping"));
  const auto twin =
      ScannedSpatula(proxy, core::testing::TestDir("twin_actor_reality", "scanned_spatula"));
  const ObjectPoseEstimator estimator(twin, twin->spec().objects);
  const auto index = [&](const char* body) {
    const auto& names = twin->spec().objects;
    return int(std::find(names.begin(), names.end(), body) - names.begin());
  };
  const int pancake = index("pancake"), griddle = index("griddle");
  EXPECT_EQ(estimator.symmetry(pancake), 0);
  EXPECT_EQ(estimator.symmetry(griddle), 1);
  EXPECT_EQ(estimator.symmetry(index("spatula")), 1);

  // The proxy's scene as scanned, then a level-1 scene with the griddle turned 0.2 rad or more.
  const sim::Env& hidden = proxy.hidden_env();
  const int real_griddle = mj_name2id(hidden.model(), mjOBJ_BODY, "griddle");
  proxy.Reset({0, 0});
  const core::Pose scanned = hidden.BodyPose(real_griddle);
  core::Pose moved;
  for (uint64_t seed = 5000;; ++seed) {
    ASSERT_LT(seed, 5100u);
    proxy.Reset({seed, 1});
    moved = hidden.BodyPose(real_griddle) * scanned.Inverse();  // base frame
    if (std::abs(core::ToRollPitchYaw(moved.rotation).z()) > 0.2) break;
  }
  // Each object found where the scene moved it; the pancake fitted 2 rad round about its middle.
  std::vector<core::Pose> found;
  for (int i = 0; i < int(twin->spec().objects.size()); ++i)
    found.push_back(moved * estimator.nominal(i));
  core::Pose fitted = found[pancake];
  fitted.rotation = core::Yaw(2.0) * fitted.rotation;
  sim::Env env(twin);
  env.Reset(0, 0);
  const int body = mj_name2id(env.model(), mjOBJ_BODY, "pancake");
  const auto edge_way = [](const sim::Env& e, const mjModel* m) {
    const Eigen::Vector3d centre =
        e.SitePose(mj_name2id(m, mjOBJ_SITE, "pancake_center")).translation;
    const Eigen::Vector3d edge = e.SitePose(mj_name2id(m, mjOBJ_SITE, "pancake_edge")).translation;
    const Eigen::Vector2d way = (edge - centre).head<2>();
    return std::atan2(way.y(), way.x());
  };
  const double real_way = edge_way(hidden, hidden.model());
  const auto off = [&](const core::Pose& pose) {
    env.PlaceBody(body, pose);
    return std::abs(std::remainder(edge_way(env, env.model()) - real_way, 2 * M_PI));
  };
  EXPECT_LT(off(estimator.NearestLookAlike(pancake, fitted, estimator.NominalOn(pancake, found))),
            0.05);
  EXPECT_GT(off(estimator.NearestLookAlike(pancake, fitted)), 0.15)
      << "at the twin's own turn, the near edge would not turn with the griddle";
  EXPECT_GT(off(fitted), 1.0) << "the fit's own turn";
}

// The scanned twin measures the blade in the hand as the drawing's twin does
// (CarriesTheSpatulaAndMeasuresHowFarItsBladeReaches) when the pancake stands near the robot, 56
// cm out or less. The arm then cannot back the blade up to the pancake: it hangs over the
// pancake and the griddle when it is looked at. Until stop 87 the points near its tip went to
// those two, whose scanned meshes the actor took to be as large as their bounding spheres (the
// griddle's stood 15 cm over the table): the blade, measured 15 mm short, drove into the
// griddle's side under the pancake (6 of 7 failures at levels 2 and 3).
TEST(TwinActorOnReality, TheScannedTwinMeasuresTheBladeOverANearPancake) {
  learn::PinMathThreads(1);
  Scene scene("spatula_flipping");
  scene.task =
      ScannedSpatula(scene.proxy, core::testing::TestDir("twin_actor_reality", "near_pancake"));
  const sim::Env& hidden = scene.proxy.hidden_env();
  const int pancake = mj_name2id(hidden.model(), mjOBJ_BODY, "pancake");
  uint64_t seed = 5000;
  for (;; ++seed) {
    ASSERT_LT(seed, 5200u);
    scene.proxy.Reset({seed, 1});
    if ((hidden.base().Inverse() * hidden.BodyPose(pancake)).translation.head<2>().norm() < 0.556)
      break;
  }
  RelookOptions relook;
  relook.measure_reach = true;
  relook.max_looks = 1;
  TwinActor actor(scene.task, scene.proxy, scene.TaskCameraLook(), true, {}, {}, relook);
  // Grasped by step 21; looked at in the hand when the lift, 25 steps at most, is done.
  scene.Run(actor, seed, 1, 50, false);
  const int real = mj_name2id(hidden.model(), mjOBJ_BODY, "spatula");
  ASSERT_GT(hidden.BodyPose(real).translation.z(), 0.05)  // 4.6 cm on the table
      << "the proxy's gripper is not holding the spatula up";
  const double real_reach = Reach(hidden, "spatula", "spatula_grasp", "blade_tip");
  sim::Env drawn(scene.task);
  ASSERT_GT(std::abs(Reach(drawn, "spatula", "spatula_grasp", "blade_tip") - real_reach), 0.008);
  EXPECT_NEAR(Reach(actor.twin(), "spatula", "spatula_grasp", "blade_tip"), real_reach, 0.004);
}

// The scanned griddle is found turned as the scene turned it, to 2 deg. Level 1 turns it up to 17
// deg, and every failure of the scanned twin at stop 87 was a scene turned 14-17 deg. This is the
// first level-1 scene from seed 5000 turned 0.25 rad or more (-15.5 deg), looked at once from the
// task camera: found turned -15.6 deg. Not polished point to plane, as until stop 88, -4.2. (The
// two scenes before it turned 0.2 rad or more, -12.8 and -13.4 deg: -12.6 and -13.1, and -3.9 and
// -4.9 not polished; one scene is fitted in about a minute. The polished turns were measured
// before the polish was bound to 3 cm.)
TEST(PoseEstimate, TheScannedGriddleIsFoundTurnedAsTheSceneTurnedIt) {
  Scene scene("spatula_flipping");
  scene.task =
      ScannedSpatula(scene.proxy, core::testing::TestDir("twin_actor_reality", "turned_griddle"));
  const auto& objects = scene.task->spec().objects;
  ObjectPoseEstimator estimator(scene.task, objects);
  const int griddle = int(std::find(objects.begin(), objects.end(), "griddle") - objects.begin());
  const sim::Env& hidden = scene.proxy.hidden_env();
  const int real = mj_name2id(hidden.model(), mjOBJ_BODY, "griddle");
  scene.proxy.Reset({0, 0});
  const core::Pose scanned = hidden.BodyPose(real);
  const auto yaw = [](const core::Pose& p) { return core::ToRollPitchYaw(p.rotation).z(); };
  uint64_t seed = 5000;
  double turn = 0;
  for (;; ++seed) {
    ASSERT_LT(seed, 5200u);
    scene.proxy.Reset({seed, 1});
    turn = yaw(hidden.BodyPose(real) * scanned.Inverse());
    if (std::abs(turn) >= 0.25) break;
  }
  const reality::Observation o = scene.proxy.Reset({seed, 1});
  std::vector<Eigen::Vector3d> points;
  for (const auto& frame : scene.TaskCameraLook()({o, {}, ""})) {
    const auto p = estimator.Foreground(FramePoints(frame), o.q, o.gripper_width);
    points.insert(points.end(), p.begin(), p.end());
  }
  const auto estimate = estimator.Estimate(points);
  const double fitted = yaw(estimate[griddle].pose * estimator.nominal(griddle).Inverse());
  EXPECT_LT(std::abs(std::remainder(fitted - turn, 2 * M_PI)) * 180 / M_PI, 2.0)
      << "seed " << seed << ": turned " << turn * 180 / M_PI << " deg, fitted "
      << fitted * 180 / M_PI;
}

// Level 3 shoves the block a few cm while the peg is on its way. Looking once, the actor puts
// the peg where the block was; looking again from over the hole (the task's expert marks that
// step `look`), it finds the block moved, comes over it again and inserts the peg. The trials are
// eval's level-3 trials 5 and 7 (seed 5000), where the shove moved the block before the look
// (until stop 48 trials 1 and 6: with each fit settled they still find the block moved and
// believe it within 2 mm, but the shove also knocks the peg in the hand, and their searches by
// feel now miss).
TEST(TwinActorOnReality, LooksAgainAndFollowsAPushedBlock) {
  learn::PinMathThreads(1);
  Scene scene("peg_insertion");
  const Look look = scene.TaskCameraLook();
  for (uint64_t trial : {5, 7}) {
    const uint64_t seed = core::MixSeed(5000, 3000 + trial);
    for (int max_looks : {1, 3}) {
      RelookOptions relook;
      relook.max_looks = max_looks;
      TwinActor actor(scene.task, scene.proxy, look, true, {}, {}, relook);
      scene.Run(actor, seed, 3, scene.spec.horizon, true);
      const bool success = scene.proxy.QuerySuccess() == reality::SuccessAnswer::kSuccess;
      if (max_looks == 1) {
        EXPECT_EQ(actor.looks(), 1);
        EXPECT_FALSE(success) << "trial " << trial << ", looking once";
      } else {
        EXPECT_GE(actor.redone_steps(), 1) << "trial " << trial;
        EXPECT_TRUE(success) << "trial " << trial << ", looking again";
        // The block is believed where the hidden world has it now, to a few mm.
        EXPECT_LT(SiteError(*scene.task, actor.estimates(), scene.proxy.hidden_env(), "hole_top"),
                  0.004)
            << "trial " << trial;
      }
    }
  }
}

// The shove can come after the look from over the hole, as the peg goes down: in eval's level-3
// trials 0, 17 and 20 (seed 5000) it moved the block 8-13 mm with the peg's tip at the hole's
// mouth, farther than the search's 6 mm spiral reaches. Blocked there, the actor now looks again
// before searching (`look_when_blocked`), finds the block moved, comes over it again and inserts
// the peg. Without that look the peg stays on the block's top.
TEST(TwinActorOnReality, LooksAgainWhenBlockedAndFindsTheBlockShovedAfterTheLastLook) {
  learn::PinMathThreads(1);
  Scene scene("peg_insertion");
  const Look look = scene.TaskCameraLook();
  const uint64_t seed = core::MixSeed(5000, 3000 + 0);
  for (const bool when_blocked : {true, false}) {
    RelookOptions relook;
    relook.look_when_blocked = when_blocked;
    TwinActor actor(scene.task, scene.proxy, look, true, {}, {}, relook);
    scene.Run(actor, seed, 3, scene.spec.horizon, true);
    const bool success = scene.proxy.QuerySuccess() == reality::SuccessAnswer::kSuccess;
    if (when_blocked) {
      // The first, over the hole, when blocked, and over the hole again (the step done again).
      EXPECT_EQ(actor.looks(), 4);
      EXPECT_EQ(actor.redone_steps(), 1);
      EXPECT_TRUE(success) << "looking when blocked";
      EXPECT_LT(SiteError(*scene.task, actor.estimates(), scene.proxy.hidden_env(), "hole_top"),
                0.004);
    } else {
      EXPECT_EQ(actor.looks(), 2) << "the look from over the hole only";
      EXPECT_FALSE(success) << "not looking when blocked";
      EXPECT_GT(SiteError(*scene.task, actor.estimates(), scene.proxy.hidden_env(), "hole_top"),
                0.006);
    }
  }
}

// In eval's level-3 trial 3 (seed 5000) the shove moves the block 3 mm before the look from over
// the hole. That look takes 3 mm for the estimate's scatter (under `moved`, 5 mm), and the peg
// comes down on the rim, where the search by feel does not shift it: the tool moves, the peg slides
// up to 3 mm in the fingers and stays where it stands. Blocked, the actor looks again, and there a
// shift of 2.5 mm counts (`moved_when_blocked`): it follows the block, comes over the hole again
// and the peg goes in. With 5 mm there too, the block stays where it was believed. The look is
// taken where the peg is blocked, as then: from aside (stop 91) the step over the hole is done
// again whatever the look finds, and the peg goes in either way.
TEST(TwinActorOnReality, BlockedItTakesASmallerShiftForAMove) {
  learn::PinMathThreads(1);
  Scene scene("peg_insertion");
  const Look look = scene.TaskCameraLook();
  const uint64_t seed = core::MixSeed(5000, 3000 + 3);
  for (const double when_blocked : {RelookOptions{}.moved_when_blocked, 0.005}) {
    RelookOptions relook;
    relook.moved_when_blocked = when_blocked;
    relook.look_aside = 0;
    TwinActor actor(scene.task, scene.proxy, look, true, {}, {}, relook);
    scene.Run(actor, seed, 3, scene.spec.horizon, true);
    const bool success = scene.proxy.QuerySuccess() == reality::SuccessAnswer::kSuccess;
    const double error =
        SiteError(*scene.task, actor.estimates(), scene.proxy.hidden_env(), "hole_top");
    // The first, over the hole, when blocked, and, the step done again, over the hole again.
    EXPECT_EQ(actor.looks(), when_blocked < 0.003 ? 4 : 3);
    if (when_blocked < 0.003) {
      EXPECT_EQ(actor.redone_steps(), 1);
      EXPECT_TRUE(success) << "moved when blocked " << when_blocked;
      EXPECT_LT(error, 0.002);
    } else {
      EXPECT_EQ(actor.redone_steps(), 0);
      EXPECT_FALSE(success) << "moved when blocked " << when_blocked;
      EXPECT_GT(error, 0.0025);
    }
  }
}

// Each finger has two pads, one above the other, reaching 4.4 cm above the tool's point and 0.9 cm
// below it. Grasped 1.5 cm below its top (at `peg_grasp`, as the expert did until stop 49), the
// peg is held by the lower pads only, and on the proxy (whose gripper closes with 45 N where the
// twin's does with 70) it slipped in the fingers as the arm swung round with the wrist at its stop
// (two finger directions, as until stop 50): in eval's level-3 trial 4 (seed 5000) its tip moved
// 1 cm in the tool's frame and the insertion failed. Grasped at its middle, as the task's expert
// now does, both pads hold it, and it stays put and goes in, the arm swinging as before. (With
// four finger directions the arm no longer swings in this trial, and the peg held near its top
// stays put too: docs/samrl.md, "the wrist at its limit".) The frame is registered to the arm
// alone, as when the trial was found: registered to the table's top as well (stop 77), the
// hole's estimate differs a little and the arm no longer swings round in this trial. And the look
// when blocked is taken where the peg is blocked, as then: from aside (stop 91) the peg held near
// its top slips 5 mm, not 6.
TEST(TwinActorOnReality, HoldsThePegAtItsMiddleWhereItDoesNotSlipInTheFingers) {
  learn::PinMathThreads(1);
  Scene scene("peg_insertion");
  const Look look = scene.TaskCameraLook();
  const uint64_t seed = core::MixSeed(5000, 3000 + 4);
  const sim::Env& hidden = scene.proxy.hidden_env();
  const int tip = mj_name2id(hidden.model(), mjOBJ_SITE, "peg_tip");
  ASSERT_GE(tip, 0);
  // Two finger directions; the grasp step down to the peg (its offset from `peg_grasp`) as the
  // task has it, or to the site.
  const sim::TaskSpec two = scene.TwoFingerDirections();
  sim::TaskSpec at_top = two;
  auto& down = at_top.expert.steps.at(1);
  ASSERT_EQ(down.site, "peg_grasp");
  ASSERT_LT(down.offset[2], -0.02) << "the task's expert no longer grasps the peg below the site";
  down.offset[2] = 0;
  for (const bool middle : {true, false}) {
    const auto task = std::make_shared<const sim::Task>(middle ? two : at_top);
    RelookOptions in_place;
    in_place.look_aside = 0;
    TwinActor actor(task, scene.proxy, look, true, ArmAlone(), {}, in_place);
    // The peg's tip in the tool's frame, from when it is first lifted clear of the table.
    std::optional<Eigen::Vector3d> lifted;
    double moved = 0;
    scene.Run(actor, seed, 3, scene.spec.horizon, true,
              [&](const reality::Observation&, const sim::Action&) {
                const Eigen::Vector3d at = hidden.SitePose(tip).translation;
                if (at.z() < 0.05 && !lifted) return;
                const Eigen::Vector3d in_tool = hidden.EePose().Inverse() * at;
                if (!lifted) lifted = in_tool;
                moved = std::max(moved, (in_tool - *lifted).norm());
              });
    ASSERT_TRUE(lifted) << (middle ? "at the middle" : "at the top") << ": the peg was not lifted";
    const bool success = scene.proxy.QuerySuccess() == reality::SuccessAnswer::kSuccess;
    if (middle) {
      EXPECT_LT(moved, 0.003) << "held at its middle, the peg slipped in the fingers";
      EXPECT_TRUE(success) << "held at its middle";
    } else {
      EXPECT_GT(moved, 0.006) << "held near its top, the peg did not slip in the fingers";
      EXPECT_FALSE(success) << "held near its top";
    }
  }
}

// The peg is square, so the task's expert may turn the fingers to any of four directions across
// the peg and the hole (`symmetry: 4`), and takes the nearest. With two (+-fingers, as until stop
// 50), eval's level-3 trial 18 (seeds 7000) had joint 7 run to its stop on the proxy, the other
// joints swing the arm round to make up the turn, and the peg never went in. Stop 82 found why
// the wrist had to turn that far: the look that found the block pushed fitted it a quarter turn
// from where it was believed (it looks the same), and with two directions the step done again
// turned the hand a quarter turn after it. A block seen again is now the look-alike nearest where
// it was believed: the wrist stays well off its stops, and the peg goes in, with four directions
// and with two (the four directions are tested in the twin:
// ScriptedExpert.TheWristTurnsToTheNearestOfTheFingerDirectionsThatServeAlike). The frame is
// registered to the arm alone, as when the trial was found.
TEST(TwinActorOnReality, TheWristStaysOffItsStopsWhenThePushedBlockIsSeenAgain) {
  learn::PinMathThreads(1);
  Scene scene("peg_insertion");
  const Look look = scene.TaskCameraLook();
  const uint64_t seed = core::MixSeed(7000, 3000 + 18);
  const sim::TaskSpec two = scene.TwoFingerDirections();
  const mjModel* m = scene.task->model();
  const int joint = mj_name2id(m, mjOBJ_JOINT, "joint7");
  ASSERT_GE(joint, 0);
  const double lo = m->jnt_range[2 * joint], hi = m->jnt_range[2 * joint + 1];
  for (const bool four : {true, false}) {
    const auto task = four ? scene.task : std::make_shared<const sim::Task>(two);
    TwinActor actor(task, scene.proxy, look, true, ArmAlone());
    double margin = hi - lo;  // the closest joint 7 came to a stop, as the robot reports it
    scene.Run(actor, seed, 3, scene.spec.horizon, true,
              [&](const reality::Observation& o, const sim::Action&) {
                margin = std::min({margin, o.q[6] - lo, hi - o.q[6]});
              });
    EXPECT_GE(actor.redone_steps(), 1) << "the push seen, four directions: " << four;
    EXPECT_GT(margin, 0.3) << "rad from joint 7's stops, four directions: " << four;
    EXPECT_EQ(scene.proxy.QuerySuccess(), reality::SuccessAnswer::kSuccess)
        << "four directions: " << four;
  }
}

// In eval's level-2 trial 2 (seed 5000) on the hidden peg, the first look's frame put the peg and
// the block 3-5 mm off along y, both the same way (the frame's own error). The fingers closed on
// the peg where that frame put it, so its error stayed in the hand, while the look from over the
// hole put the block right: the peg was believed over the hole and stood 4 mm beside it, pressed
// on the block, until the steps ran out. Found in the hand in the same frames as the block
// (`measure_held`, with `refine`), the peg's believed offset from the hole is the real one's to
// within a millimetre, and it goes in. Each start on every point, as then: on 500 (stop 89) the
// peg goes in measured in the hand or not.
TEST(TwinActorOnReality, FindsThePegInTheHandInTheFramesThatFindTheHole) {
  learn::PinMathThreads(1);
  HiddenPeg peg;
  Scene& scene = peg.scene;
  const Look& active = peg.active;
  const uint64_t seed = core::MixSeed(5000, 2000 + 2);
  for (const bool measure : {true, false}) {
    RelookOptions relook;
    relook.measure_held = relook.refine = measure;
    TwinActor actor(scene.task, scene.proxy, active, true, EveryPoint(), {}, relook);
    // How far the peg's tip is believed from the hole, less how far it is (table plane), once the
    // look from over the hole is done.
    std::optional<double> error;
    scene.Run(actor, seed, 2, scene.spec.horizon, true,
              [&](const reality::Observation&, const sim::Action&) {
                if (error || actor.looks() < 2) return;
                const auto offset = [](const sim::Env& env) {
                  const auto site = [&](const char* name) {
                    return env.SitePose(mj_name2id(env.model(), mjOBJ_SITE, name)).translation;
                  };
                  return Eigen::Vector2d((site("peg_tip") - site("hole_top")).head<2>());
                };
                error = (offset(actor.twin()) - offset(scene.proxy.hidden_env())).norm();
              });
    const bool success = scene.proxy.QuerySuccess() == reality::SuccessAnswer::kSuccess;
    ASSERT_TRUE(error.has_value()) << "measure " << measure;
    if (measure) {
      EXPECT_LT(*error, 0.0015);
      EXPECT_TRUE(success) << "the peg found in the hand";
    } else {
      EXPECT_GT(*error, 0.003);
      EXPECT_FALSE(success) << "the peg carried where the first look put it";
    }
  }
}

// In eval's level-3 trial 20 on the hidden peg (seeds 5000), the peg comes down 3.5 mm beside the
// hole and is blocked. The look when blocked, with the arm over the block, fits the block to a
// sliver of 56 points, none against, 20 mm from where it stands. Taken for a push, the peg was
// carried there (stop 80). A fit needs RelookOptions::min_points (120) to be acted on: the block
// stays believed where it is, to a few mm. (The peg does not go in either way: pressed on the
// block's top, the search by feel does not bring its tip over the hole.) Three looks, as then: with
// a fourth (the default since stop 81), the look after the step done again puts the block right.
// And the hand turned as then: kept clear of the screen (stop 81), it comes over the hole another
// way, and the looks see the block otherwise. And the fits not polished, as then: polished (stop
// 88), the trial takes two looks, no sliver is acted on, and the hole is believed within 0.1 mm.
// And each start on every point: on 500 (stop 89), with 50 points enough the hole is believed
// within 1.6 mm, and with the default a step is done again. And the look when blocked taken where
// the peg is blocked: from aside (stop 91) it sees the block, not a sliver, and with 50 points
// enough the hole is believed within 2 mm.
TEST(TwinActorOnReality, DoesNotFollowABlockFittedToASliver) {
  learn::PinMathThreads(1);
  HiddenPeg peg;
  for (const int min_points : {RelookOptions{}.min_points, 50}) {
    RelookOptions relook = HiddenPeg::EvalRelook();
    relook.min_points = min_points;
    relook.max_looks = 3;
    relook.hand_clearance = false;
    // The frame also sees through the sliver's fit (918 points; 36 where the block was believed),
    // and that check refuses it too (stop 83): off here, for the count of points alone.
    relook.seen_through_points = 0;
    relook.look_aside = 0;
    const HiddenPeg::Outcome trial = peg.RunTrial(20, 3, relook, EveryPoint(Unpolished()));
    EXPECT_EQ(trial.looks, 3) << "min points " << min_points;
    if (min_points > 100) {
      EXPECT_EQ(trial.redone, 0);
      EXPECT_LT(trial.hole_error, 0.005);
    } else {
      EXPECT_EQ(trial.redone, 1) << "the sliver taken for a push";
      EXPECT_GT(trial.hole_error, 0.015);
    }
  }
}

// In eval's level-3 trial 18 on the hidden peg (seeds 7000) the look from over the hole sees one
// face of the block and its fit slides 43 mm along it. The frame shows the table where the fit
// puts the block (1512 points seen through it there, 10 where it was believed): that fit is not
// followed, the block stays believed where it stands, and the peg goes in. Unchecked, the peg was
// carried 4 cm off. Each start on every point, as then: on 500 (stop 89) no fit slides along the
// face, and unchecked the peg goes in too.
TEST(TwinActorOnReality, DoesNotFollowAFitTheFrameSeesThrough) {
  learn::PinMathThreads(1);
  HiddenPeg peg(7000);
  for (const int points : {RelookOptions{}.seen_through_points, 0}) {
    RelookOptions relook = HiddenPeg::EvalRelook();
    relook.seen_through_points = points;
    const HiddenPeg::Outcome trial = peg.RunTrial(18, 3, relook, EveryPoint());
    if (points > 0) {
      EXPECT_LT(trial.hole_error, 0.005);
      EXPECT_TRUE(trial.success) << "the fit seen through not followed";
    } else {
      EXPECT_GT(trial.hole_error, 0.03);
      EXPECT_FALSE(trial.success) << "the block believed 4 cm off";
    }
  }
}

// In eval's level-3 trial 35 on the hidden peg (seeds 9000) the look from over the hole fits the
// block 35 mm away. The frames see through that place (1712 points) and through where the block
// was believed (218): it is in neither. The fit is not followed, the step over the hole is done
// again and the actor looks again; the fifth look finds the block, and the peg goes in. Unchecked
// (stop 89 followed such a fit), the block is believed where that fit put it, about 5 cm from
// where it stands, and the trial is lost.
TEST(TwinActorOnReality, LooksAgainWhenTheFramesSeeThroughTheFitAndTheBelief) {
  learn::PinMathThreads(1);
  HiddenPeg peg(9000);
  for (const int points : {RelookOptions{}.seen_through_points, 0}) {
    RelookOptions relook = HiddenPeg::EvalRelook();
    relook.seen_through_points = points;
    const HiddenPeg::Outcome trial = peg.RunTrial(35, 3, relook);
    if (points > 0) {
      EXPECT_EQ(trial.looks, 5);
      EXPECT_LT(trial.hole_error, 0.005);
      EXPECT_TRUE(trial.success) << "looked again, and found the block";
    } else {
      EXPECT_GT(trial.hole_error, 0.02);
      EXPECT_FALSE(trial.success) << "the block believed where the frames see through it";
    }
  }
}

// In eval's level-3 trial 15 on the hidden peg (seeds 9000) the shove moves the block 19 mm as the
// peg is carried over it. The look from over the hole and the look when blocked see 0.25% and
// 0.08% of the block past the hand and find nothing moved; the search by feel runs out the trial
// 16-18 mm off (stop 84's trace). Looking from 8 cm up and back (`look_aside`), the frames find
// the block 18 mm from where it was believed, the peg comes over it again, and goes in.
TEST(TwinActorOnReality, LooksFromAsideWhenBlocked) {
  learn::PinMathThreads(1);
  HiddenPeg peg(9000);
  for (const double aside : {RelookOptions{}.look_aside, 0.0}) {
    RelookOptions relook = HiddenPeg::EvalRelook();
    relook.look_aside = aside;
    const HiddenPeg::Outcome trial = peg.RunTrial(15, 3, relook);
    if (aside > 0) {
      EXPECT_TRUE(trial.success) << "looked from aside";
      EXPECT_LT(trial.hole_error, 0.005);
      EXPECT_EQ(trial.redone, 1) << "the block found moved from aside";
    } else {
      EXPECT_FALSE(trial.success) << "looked over the block";
      EXPECT_GT(trial.hole_error, 0.01);
    }
  }
}

// In eval's level-3 trial 7 on the hidden peg (seeds 9000) the first look does not see the block
// and the actor looks again at once; the look from over the hole and the one when blocked find it
// shoved 32 mm, the peg comes over it again and is blocked again. The fifth look finds the block
// 10 mm farther, and the peg goes in. With four looks (stop 81-83's default) it had none left,
// and the search by feel ran out the trial. The fits are not polished, as then: polished (stop
// 88), the fourth look puts the block 6 mm nearer where it is, the fifth looks from elsewhere and
// sees none of it, and the trial is lost (eval's log of stop 88). And each start on every point:
// on 500 (stop 89) the trial takes four looks and is lost (as in eval's log of stop 89, polished).
// And the looks when blocked taken where the peg is blocked: with the first from aside (stop 91),
// four looks put the peg in too.
TEST(TwinActorOnReality, AFifthLookFindsTheBlockAfterAFirstLookThatMissedIt) {
  learn::PinMathThreads(1);
  HiddenPeg peg(9000);
  for (const int looks : {RelookOptions{}.max_looks, 4}) {
    RelookOptions relook = HiddenPeg::EvalRelook();
    relook.max_looks = looks;
    relook.look_aside = 0;
    const HiddenPeg::Outcome trial = peg.RunTrial(7, 3, relook, EveryPoint(Unpolished()));
    EXPECT_EQ(trial.looks, looks);
    if (looks > 4) {
      EXPECT_TRUE(trial.success) << "five looks";
      EXPECT_LT(trial.hole_error, 0.005);
    } else {
      EXPECT_FALSE(trial.success) << "four looks";
    }
  }
}

// In eval's level-3 trial 6 on the hidden peg (seeds 5000), the shove moves the block 22 mm toward
// the screen. The look from over the hole finds it, and the expert comes over it again, the
// fingers (the hand's 19 cm) pointing at the screen as the nearest of the square peg's four ways:
// the hand met the screen and stood still for 24 steps, and the peg never went in. Kept clear of
// what the frames showed that no object explains (`hand_clearance`), the hand comes over the
// block the other way, and the peg goes in.
TEST(TwinActorOnReality, KeepsTheHandClearOfAScreenItSaw) {
  learn::PinMathThreads(1);
  HiddenPeg peg;
  Scene& scene = peg.scene;
  const Look& active = peg.active;
  const uint64_t seed = core::MixSeed(5000, 3000 + 6);
  for (const bool clearance : {true, false}) {
    RelookOptions relook = HiddenPeg::EvalRelook();
    relook.hand_clearance = clearance;
    TwinActor actor(scene.task, scene.proxy, active, true, {}, {}, relook);
    int on_screen = 0;
    scene.Run(actor, seed, 3, scene.spec.horizon, true,
              [&](const reality::Observation&, const sim::Action&) {
                const nlohmann::json state = scene.proxy.GraderState();
                for (const auto& c : state.at("arm_contacts"))
                  if (c.get<std::string>().find("screen") != std::string::npos) {
                    ++on_screen;
                    break;
                  }
              });
    const bool success = scene.proxy.QuerySuccess() == reality::SuccessAnswer::kSuccess;
    if (clearance) {
      EXPECT_LT(on_screen, 3);
      EXPECT_TRUE(success) << "the hand kept clear";
    } else {
      EXPECT_GT(on_screen, 10);
      EXPECT_FALSE(success) << "the hand against the screen";
    }
  }
}

// On its way down to the hole the hand keeps the finger direction it came over the block with.
// It turned a quarter turn there in two ways (hidden peg, level 3, seeds 5000; stop 82). In trial
// 4 the look from over the hole fitted the square block a quarter turn from where it was
// believed (it looks the same), and the step under way, aligned to the block's frame, turned the
// hand after it. In trial 5 the hand clearance, checked at the search step's own target, 25 mm
// lower than the hover, took another direction with the peg 6 mm over the hole, and the tip came
// down beside it. Now a block seen again is the look-alike nearest where it was believed, and the
// clearance chooses once for the steps that continue one another (over the hole, down, search),
// clear at all their targets. Once the tip is within a centimetre of the hole's axis and 3 cm
// over it, the tool turns less than 0.1 rad, and the peg goes in.
TEST(TwinActorOnReality, KeepsTheHandsDirectionOnItsWayDownToTheHole) {
  learn::PinMathThreads(1);
  HiddenPeg peg;
  Scene& scene = peg.scene;
  const sim::Env& hidden = scene.proxy.hidden_env();
  const int tip = mj_name2id(hidden.model(), mjOBJ_SITE, "peg_tip");
  const int hole = mj_name2id(hidden.model(), mjOBJ_SITE, "hole_top");
  ASSERT_GE(tip, 0);
  ASSERT_GE(hole, 0);
  for (const int trial : {4, 5}) {
    TwinActor actor(scene.task, scene.proxy, peg.active, true, {}, {}, HiddenPeg::EvalRelook());
    std::optional<core::Quat> over;  // the tool's rotation when the tip first came over the hole
    double turned = 0;
    scene.Run(actor, core::MixSeed(5000, 3000 + trial), 3, scene.spec.horizon, true,
              [&](const reality::Observation&, const sim::Action&) {
                const Eigen::Vector3d d =
                    hidden.SitePose(tip).translation - hidden.SitePose(hole).translation;
                if (d.head<2>().norm() > 0.01 || d.z() > 0.03) return;
                const core::Quat tool = hidden.EePose().rotation;
                if (!over) over = tool;
                turned = std::max(turned, core::AngleBetween(*over, tool));
              });
    EXPECT_TRUE(over.has_value()) << "trial " << trial << ": the tip never came over the hole";
    EXPECT_LT(turned, 0.1) << "rad, trial " << trial;
    EXPECT_EQ(scene.proxy.QuerySuccess(), reality::SuccessAnswer::kSuccess) << "trial " << trial;
  }
}

// On the occluded peg, the panel hides the hole block from the task camera's pose: from there the
// hole is either not found or found somewhere else (the block fitted to what the twin's panel does
// not explain of the real one). From the view the active look chooses in the twin it is found,
// to within a centimetre.
TEST(ActiveLook, FindsTheHoleTheFixedViewCannotSee) {
  learn::PinMathThreads(1);
  Scene scene("peg_insertion_occluded");
  const sim::CameraIntrinsics capture = ScaleIntrinsics(scene.camera.intrinsics, 8);
  real2sim::TwinGeometry geometry(scene.spec, 600);
  ViewSearchOptions search;
  search.samples = 24;
  search.steps = 30;
  const Look active =
      ActiveLook(scene.proxy, geometry, scene.spec.objects, ObjectsMount(*scene.task),
                 {40, 30, 36, 36, 19.5, 14.5}, capture, search, 2);
  const Look fixed = FixedLook(scene.proxy, scene.camera.pose, capture);
  for (uint64_t seed : {100, 101}) {
    const auto from_fixed = scene.Estimate(seed, fixed);
    EXPECT_TRUE(!from_fixed[1].seen ||
                SiteError(*scene.task, from_fixed, scene.proxy.hidden_env(), "hole_top") > 0.02)
        << "seed " << seed;
    const auto from_active = scene.Estimate(seed, active);
    EXPECT_TRUE(from_active[1].seen) << "seed " << seed;
    EXPECT_LT(SiteError(*scene.task, from_active, scene.proxy.hidden_env(), "hole_top"), 0.01)
        << "seed " << seed;
  }
}

// On peg_insertion_hidden a screen stands where the scene puts it, past the block or beside it.
// In eval's level-1 trial 4 (seed 5000) it stands between the block and the first view the active
// look chooses (in the twin, which has the screen elsewhere): the block is fitted to the screen,
// with far more of the frame against the fit than for it, and the actor does not trust it. It
// looks again at once. Told what the first frame showed that no object explains (the screen, as
// columns on the table), the look chooses a view around it and finds the block to within a
// centimetre. Not told, it looks from about the same view and does not find it.
TEST(ActiveLook, LooksAroundAScreenItSawInTheWay) {
  learn::PinMathThreads(1);
  HiddenPeg peg;
  Scene& scene = peg.scene;
  const Look& active = peg.active;
  const uint64_t seed = core::MixSeed(5000, 1000 + 4);
  for (const bool occluders : {true, false}) {
    RelookOptions relook;
    relook.occluders = occluders;
    TwinActor actor(scene.task, scene.proxy, active, true, {}, {}, relook);
    scene.Run(actor, seed, 1, 1, false);
    EXPECT_EQ(actor.looks(), 2) << "occluders " << occluders;
    const double error =
        SiteError(*scene.task, actor.estimates(), scene.proxy.hidden_env(), "hole_top");
    if (occluders) {
      EXPECT_LT(error, 0.01) << "told what was in the way";
      EXPECT_GT(actor.estimates()[1].score, 0);
    } else {
      EXPECT_GT(error, 0.02) << "not told what was in the way";
    }
  }
}

}  // namespace
}  // namespace twinforge::samrl
