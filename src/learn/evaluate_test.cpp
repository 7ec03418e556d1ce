#include "learn/evaluate.h"

#include <gtest/gtest.h>

#include "core/error.h"
#include "core/test_support.h"
#include "learn/policy_net.h"
#include "learn/torch_runtime.h"

namespace twinforge::learn {
namespace {

std::filesystem::path UntrainedPolicy(const std::string& name, bool discrete) {
  const auto dir = core::testing::TestDir("evaluate_test", name);
  PolicyConfig config;
  config.points = 128;
  config.discrete = discrete;
  config.action_dim = discrete ? 14 : 7;
  torch::manual_seed(5);
  PolicyNet net(config);
  SavePolicy(net, dir / "policy.pt");
  return dir / "policy.pt";
}

// Every episode depends only on its seed: the same outcomes on one thread or two.
TEST(EvaluatePolicy, OutcomesDoNotDependOnTheThreadCount) {
  PinMathThreads(1);
  const auto policy = UntrainedPolicy("threads", true);
  auto task = std::make_shared<const sim::Task>(sim::LoadTaskSpec("open_drawer"));
  PolicyEvalOptions options;
  options.episodes = 4;
  options.level = 1;
  options.threads = 1;
  const PolicyEvalReport one = EvaluatePolicy(policy, task, options);
  options.threads = 2;
  const PolicyEvalReport two = EvaluatePolicy(policy, task, options);
  EXPECT_EQ(one.episodes, 4);
  EXPECT_EQ(one.steps, two.steps);
  EXPECT_EQ(one.successes, two.successes);
}

TEST(EvaluatePolicy, APolicyForOtherActionsIsRefusedByName) {
  const auto policy = UntrainedPolicy("mismatch", true);
  auto task = std::make_shared<const sim::Task>(sim::LoadTaskSpec("peg_insertion"));
  try {
    EvaluatePolicy(policy, task, {});
    FAIL() << "a discrete policy ran a continuous task";
  } catch (const core::Error& e) {
    EXPECT_NE(std::string(e.what()).find("policy.pt"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("peg_insertion"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace twinforge::learn
