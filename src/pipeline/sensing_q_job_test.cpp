// The sensing-aware Q learned from simulated episodes does its job; slow (CTest label "slow",
// 10-15 min on 2 cores), so CI's short suite skips it.
#include <gtest/gtest.h>

#include "core/test_support.h"
#include "learn/torch_runtime.h"
#include "pipeline/reality_eval.h"
#include "pipeline/sensing_q_training.h"
#include "reality/proxy_reality.h"
#include "samrl/twin_actor.h"
#include "sim/camera.h"

namespace twinforge::pipeline {
namespace {

// Successes of the twin actor in `episodes` simulated episodes of the twin (seeds 9000), looking
// once from `view` at the frame size train samrl used.
int SuccessesFromView(const sim::TaskSpec& twin, const core::Pose& view, int episodes,
                      int capture_scale, const std::filesystem::path& log) {
  const auto robot =
      reality::ProxyReality::SimulatedTwin(twin, reality::ProxyReality::Sensor::kCalibrated);
  samrl::RelookOptions once;
  once.max_looks = 1;
  samrl::TwinActor actor(
      std::make_shared<const sim::Task>(twin), *robot,
      samrl::FixedLook(
          *robot, view,
          samrl::ScaleIntrinsics(sim::MakeCamera(twin.camera).intrinsics, capture_scale)),
      true, {}, {}, once);
  RealityEvalOptions o;
  o.levels = {1};
  o.trials = episodes;
  o.seed = 9000;
  const RealityEvalReport r = EvaluateOperatorOnReality(
      *robot, {&actor, [&](uint64_t seed) { actor.Begin(seed); }, {{"actor", "twin"}}, nullptr},
      twin, o, log);
  return r.levels.at(0).successes;
}

// Fitted to the returns of 48 simulated episodes on the occluded peg's twin, each from a random
// view on the mount, the Q chooses a view from which the twin actor, looking once, succeeds in the
// twin more often than from the random views, and more often than from the task camera's pose,
// where the panel hides the hole. Measured (deterministic): 9/48 from the random views; from the
// Q's view 3/6 at stop 36, 6/6 at stop 44 (the expert searching for the hole since stop 43); 0/6
// from the task camera's. Since stop 52 (a registration that slid is not used) the random views
// succeed in most of the 48 (42-43 at stop 77), and 15 points over them is out of reach: the Q's
// view has to be one that works (5 or 6 of 6, at least the random views' rate), and the task
// camera's, behind the panel, not.
TEST(TrainSensingQ, ItsQsViewSucceedsMoreOftenThanRandomViews) {
  learn::PinMathThreads(1);
  const sim::TaskSpec twin = sim::LoadTaskSpec("peg_insertion_occluded");
  const std::filesystem::path dir = core::testing::TestDir("sensing_q_job");
  SensingQTrainOptions o;
  o.episodes = 48;
  o.capture_scale = 8;
  // What is measured here: the first view, which Q chooses from the view alone (as before the
  // plan was Q's action; at a first look the plan is always the first step).
  o.max_looks = 1;
  o.plan = false;
  const SensingQTrainReport r = TrainSensingQ(twin, o, dir / "q");
  const double random_rate = double(r.successes) / r.episodes;
  const samrl::OrbitMount mount = samrl::ObjectsMount(sim::Task(twin));
  const int chosen =
      SuccessesFromView(twin, samrl::OrbitPose(mount, r.chosen.azimuth, r.chosen.elevation), 6,
                        o.capture_scale, dir / "chosen.jsonl");
  const int fixed = SuccessesFromView(twin, sim::MakeCamera(twin.camera).pose, 6, o.capture_scale,
                                      dir / "fixed.jsonl");
  EXPECT_GE(chosen, 5) << "random views: " << r.successes << "/" << r.episodes;
  EXPECT_GE(chosen / 6.0, random_rate) << "random views: " << r.successes << "/" << r.episodes;
  EXPECT_LE(fixed, 1);
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace twinforge::pipeline
