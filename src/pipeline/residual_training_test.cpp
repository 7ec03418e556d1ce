#include "pipeline/residual_training.h"

#include <gtest/gtest.h>

#include <fstream>

#include "core/error.h"
#include "core/test_support.h"
#include "learn/offpolicy.h"
#include "learn/policy_net.h"
#include "learn/torch_runtime.h"
#include "pipeline/reality_eval.h"
#include "pipeline/test_support.h"
#include "reality/proxy_reality.h"

namespace twinforge::pipeline {
namespace {

using testing::Counted;
using testing::Policy;

sim::TaskSpec ShortDrawer() {
  sim::TaskSpec task = sim::LoadTaskSpec("open_drawer");
  task.horizon = 6;
  return task;
}

ResidualTrainOptions Small() {
  ResidualTrainOptions o;
  o.episodes = 3;
  o.critic_episodes = 1;
  o.updates_per_step = 1;
  o.scene_points = 256;
  o.arm_points = 64;
  o.agent.hidden = 32;
  o.agent.batch = 8;
  return o;
}

std::vector<std::string> CurveRows(const std::filesystem::path& csv) {
  std::ifstream in(csv);
  std::vector<std::string> rows;
  for (std::string line; std::getline(in, line);)
    rows.push_back(line.substr(0, line.rfind(',')));  // without the wall-clock column
  return rows;
}

// An untrained residual sends the robot the very joint targets the base policy would.
TEST(Residual, AZeroInitialisedResidualLeavesTheRobotsTargetsUnchanged) {
  learn::PinMathThreads(1);
  const auto dir = core::testing::TestDir("residual_training_test", "zero");
  for (const char* f : {"base.jsonl", "residual.jsonl"}) std::filesystem::remove(dir / f);
  reality::ProxyReality proxy(reality::ResolveWorldDir("open_drawer"));
  const sim::TaskSpec task = ShortDrawer();
  const auto policy = Policy(dir, 64, 3);
  RealityEvalOptions o;
  o.levels = {1};
  o.trials = 2;
  o.scene_points = 256;
  o.arm_points = 64;
  Counted base_robot(proxy, true);
  EvaluateOnReality(base_robot, policy, task, o, dir / "base.jsonl");

  learn::PolicyNet net = learn::LoadPolicy(policy);
  learn::OffPolicyAgent agent(net->HeadInputDim(), sim::kContinuousActionDim,
                              ResidualTrainOptions::DefaultAgent());
  agent.Save(dir / "zero.pt");
  o.residual = dir / "zero.pt";
  Counted residual_robot(proxy, true);
  EvaluateOnReality(residual_robot, policy, task, o, dir / "residual.jsonl");

  ASSERT_EQ(base_robot.sent.size(), 12u);
  ASSERT_EQ(residual_robot.sent.size(), base_robot.sent.size());
  for (std::size_t i = 0; i < base_robot.sent.size(); ++i) {
    EXPECT_EQ(residual_robot.sent[i].arm, base_robot.sent[i].arm) << "action " << i;
    EXPECT_EQ(residual_robot.sent[i].finger, base_robot.sent[i].finger) << "action " << i;
  }
  // A residual made for another base policy is refused by name.
  learn::OffPolicyAgent other(5, sim::kContinuousActionDim, ResidualTrainOptions::DefaultAgent());
  other.Save(dir / "other.pt");
  o.residual = dir / "other.pt";
  std::filesystem::remove(dir / "other.jsonl");
  EXPECT_THROW(EvaluateOnReality(residual_robot, policy, task, o, dir / "other.jsonl"),
               core::Error);
}

// Three episodes in one go, or two and then one more after a stop: the same residual and curve.
TEST(Residual, TrainsOnTheRobotAndResumesExactly) {
  learn::PinMathThreads(1);
  const auto dir = core::testing::TestDir("residual_training_test", "resume");
  reality::ProxyReality proxy(reality::ResolveWorldDir("open_drawer"));
  Counted robot(proxy, true);
  const sim::TaskSpec task = ShortDrawer();
  const auto policy = Policy(dir, 64, 4);
  const ResidualTrainOptions o = Small();
  const ResidualTrainReport whole =
      TrainResidualOnReality(robot, policy, task, o, dir / "whole.pt", true);
  EXPECT_EQ(whole.episodes, 3);
  EXPECT_EQ(whole.transitions, 3 * 5);  // no success: each episode's last step has no successor
  EXPECT_EQ(whole.updates, 3 * 6);
  EXPECT_EQ(robot.resets, 3);

  ResidualTrainOptions two = o;
  two.episodes = 2;
  TrainResidualOnReality(robot, policy, task, two, dir / "split.pt", true);
  // As if killed while committing episode 3 before its state was written: its curve row (cut
  // short) and its pending files are there; the state still says 2.
  std::ofstream(dir / "split.pt.curve.csv", std::ios::app) << "2,99,0,6,15,0.1\n2,9";
  std::ofstream(dir / "split.pt.pending-3") << "not an agent";
  std::ofstream(dir / "split.pt.buffer.pending-3") << "not a buffer";
  const ResidualTrainReport resumed =
      TrainResidualOnReality(robot, policy, task, o, dir / "split.pt", false);
  EXPECT_EQ(resumed.resumed_from, 2);
  EXPECT_EQ(robot.resets, 3 + 2 + 1);
  EXPECT_EQ(CurveRows(dir / "split.pt.curve.csv"), CurveRows(dir / "whole.pt.curve.csv"));
  auto a = learn::OffPolicyAgent::Open(dir / "whole.pt");
  auto b = learn::OffPolicyAgent::Open(dir / "split.pt");
  const torch::Tensor obs = torch::randn({8, a->obs_dim()}), base = torch::rand({8, 7}) * 2 - 1;
  EXPECT_TRUE(torch::equal(a->ActBatch(obs, base), b->ActBatch(obs, base)));
  EXPECT_FALSE(torch::equal(a->ActBatch(obs, base), base)) << "the actor never moved";
  EXPECT_EQ(a->updates(), b->updates());

  // The trained residual belongs to its base policy: eval refuses it on another, by name.
  RealityEvalOptions eval;
  eval.levels = {1};
  eval.trials = 1;
  eval.scene_points = 256;
  eval.arm_points = 64;
  eval.residual = dir / "whole.pt";
  std::filesystem::remove(dir / "eval.jsonl");
  try {
    EvaluateOnReality(robot, Policy(dir, 64, 6), task, eval, dir / "eval.jsonl");
    FAIL() << "a residual ran on a policy it was not trained on";
  } catch (const core::Error& e) {
    EXPECT_NE(std::string(e.what()).find("whole.pt"), std::string::npos) << e.what();
  }

  // Without residual mode the same loop trains an agent from scratch (the baseline): its
  // actions are its own.
  ResidualTrainOptions scratch = o;
  scratch.episodes = 1;
  scratch.agent.residual = false;
  TrainResidualOnReality(robot, policy, task, scratch, dir / "scratch.pt", true);
  auto alone = learn::OffPolicyAgent::Open(dir / "scratch.pt");
  EXPECT_FALSE(alone->options().residual);
  EXPECT_FALSE(torch::equal(alone->ActBatch(obs, base), base));

  // Another base policy's checkpoint is not continued.
  try {
    TrainResidualOnReality(robot, Policy(dir, 64, 5), task, o, dir / "split.pt", false);
    FAIL() << "a checkpoint of another base policy was resumed";
  } catch (const core::Error& e) {
    EXPECT_NE(std::string(e.what()).find("split.pt.state.json"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace twinforge::pipeline
