#include "pipeline/reality_eval.h"

#include <gtest/gtest.h>

#include <fstream>

#include "core/error.h"
#include "core/fs.h"
#include "core/test_support.h"
#include "learn/policy_net.h"
#include "learn/torch_runtime.h"
#include "pipeline/test_support.h"
#include "reality/proxy_reality.h"

namespace twinforge::pipeline {
namespace {

using testing::Counted;
using testing::Policy;

TEST(BootstrapInterval, BracketsTheRateAndNarrowsWithMoreTrials) {
  core::Rng rng(1);
  const auto [lo50, hi50] = BootstrapInterval(45, 50, 2000, rng);
  EXPECT_LT(lo50, 0.9);
  EXPECT_GT(hi50, 0.9);
  // The binomial standard error at 90% of 50 is 4.2 points: the interval spans about +-8.
  EXPECT_NEAR(hi50 - lo50, 0.165, 0.04);
  const auto [lo500, hi500] = BootstrapInterval(450, 500, 2000, rng);
  EXPECT_LT(hi500 - lo500, 0.5 * (hi50 - lo50));
  const auto [lo0, hi0] = BootstrapInterval(0, 10, 500, rng);
  EXPECT_EQ(lo0, 0.0);
  EXPECT_EQ(hi0, 0.0);
}

TEST(EvaluateOnReality, LogsEveryTrialResumesAndRefusesAnotherPolicysLog) {
  learn::PinMathThreads(1);
  const auto dir = core::testing::TestDir("reality_eval_test", "log");
  std::filesystem::remove(dir / "trials.jsonl");
  reality::ProxyReality proxy(reality::ResolveWorldDir("open_drawer"));
  Counted robot(proxy, true);
  sim::TaskSpec task = sim::LoadTaskSpec("open_drawer");
  task.horizon = 4;
  RealityEvalOptions o;
  o.levels = {1, 3};
  o.trials = 2;
  o.scene_points = 256;
  o.arm_points = 64;
  const auto policy = Policy(dir, 64, 1);
  const RealityEvalReport first = EvaluateOnReality(robot, policy, task, o, dir / "trials.jsonl");
  ASSERT_EQ(first.levels.size(), 2u);
  EXPECT_EQ(first.levels[1].level, 3);
  EXPECT_EQ(first.trials.size(), 4u);
  EXPECT_EQ(robot.resets, 4);
  EXPECT_EQ(robot.actions, 16);  // an untrained policy does not open the drawer in 4 moves
  {
    std::ifstream in(dir / "trials.jsonl");
    int lines = 0;
    for (std::string line; std::getline(in, line);) ++lines;
    EXPECT_EQ(lines, 5);  // header + one per trial
  }
  // Again: everything is read back, nothing runs.
  const RealityEvalReport again = EvaluateOnReality(robot, policy, task, o, dir / "trials.jsonl");
  EXPECT_EQ(again.resumed, 4);
  EXPECT_EQ(robot.resets, 4);
  // A killed run's cut-short last line: that trial runs again.
  {
    std::ifstream in(dir / "trials.jsonl");
    std::string all((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    all.resize(all.size() - 10);
    std::ofstream(dir / "trials.jsonl") << all;
  }
  const RealityEvalReport cut = EvaluateOnReality(robot, policy, task, o, dir / "trials.jsonl");
  EXPECT_EQ(cut.resumed, 3);
  EXPECT_EQ(robot.resets, 5);
  EXPECT_EQ(cut.trials.back().steps, first.trials.back().steps);

  try {
    EvaluateOnReality(robot, Policy(dir, 64, 2), task, o, dir / "trials.jsonl");
    FAIL() << "another policy's log was extended";
  } catch (const core::Error& e) {
    EXPECT_NE(std::string(e.what()).find("trials.jsonl"), std::string::npos) << e.what();
  }
  // As the main job asks: the other policy's trials start a new log, the old one kept beside.
  const auto old_log = core::ReadTextFile(dir / "trials.jsonl");
  RealityEvalOptions aside = o;
  aside.set_aside_other_logs = true;
  const RealityEvalReport other =
      EvaluateOnReality(robot, Policy(dir, 64, 2), task, aside, dir / "trials.jsonl");
  EXPECT_EQ(other.resumed, 0);
  EXPECT_EQ(core::ReadTextFile(dir / "trials.jsonl.previous"), old_log);
  try {
    EvaluateOnReality(robot, Policy(dir, 0, 1), task, o, dir / "state.jsonl");
    FAIL() << "a state policy ran on reality";
  } catch (const core::Error& e) {
    EXPECT_NE(std::string(e.what()).find("train distill"), std::string::npos) << e.what();
  }
}

// Without an oracle, the person at the robot is asked after every trial; with no one to ask, the
// evaluation is refused before it starts.
TEST(EvaluateOnReality, WithoutAnOracleThePersonJudges) {
  learn::PinMathThreads(1);
  const auto dir = core::testing::TestDir("reality_eval_test", "judge");
  std::filesystem::remove(dir / "trials.jsonl");
  reality::ProxyReality proxy(reality::ResolveWorldDir("open_drawer"));
  Counted robot(proxy, false);
  sim::TaskSpec task = sim::LoadTaskSpec("open_drawer");
  task.horizon = 2;
  RealityEvalOptions o;
  o.levels = {1};
  o.trials = 3;
  o.scene_points = 128;
  o.arm_points = 32;
  const auto policy = Policy(dir, 32, 1);
  EXPECT_THROW(EvaluateOnReality(robot, policy, task, o, dir / "trials.jsonl"), core::Error);
  int asked = 0;
  const RealityEvalReport r =
      EvaluateOnReality(robot, policy, task, o, dir / "trials.jsonl", [&](const TrialRecord& t) {
        ++asked;
        return t.trial != 1;  // "yes", "no", "yes"
      });
  EXPECT_EQ(asked, 3);
  EXPECT_EQ(r.levels[0].successes, 2);
  EXPECT_NEAR(r.levels[0].rate, 2.0 / 3, 1e-12);
}

}  // namespace
}  // namespace twinforge::pipeline
