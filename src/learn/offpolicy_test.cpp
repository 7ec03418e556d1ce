#include "learn/offpolicy.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>

#include "core/error.h"
#include "core/test_support.h"
#include "learn/torch_runtime.h"

namespace twinforge::learn {
namespace {

// A point in the plane steered toward a goal: obs (position, goal - position), action a 2-D
// velocity in [-1, 1]^2 (0.1 per step), reward minus the distance, success within 5 cm at the
// end of 20 steps. `bias` is added to every action, as a base policy's systematic error would be.
struct PointReach {
  static constexpr int kObs = 4, kAction = 2, kHorizon = 20;
  std::array<float, 2> pos{}, goal{};
  void Reset(core::Rng& rng) {
    for (int k = 0; k < 2; ++k) {
      pos[k] = float(rng.Uniform(-0.5, 0.5));
      goal[k] = float(rng.Uniform(-0.5, 0.5));
    }
  }
  void Obs(float* o) const {
    o[0] = pos[0];
    o[1] = pos[1];
    o[2] = goal[0] - pos[0];
    o[3] = goal[1] - pos[1];
  }
  float Step(const float* a) {
    for (int k = 0; k < 2; ++k) pos[k] += 0.1f * std::clamp(a[k], -1.0f, 1.0f);
    return -Distance();
  }
  float Distance() const { return std::hypot(goal[0] - pos[0], goal[1] - pos[1]); }
};

// A proportional controller with a systematic error: it settles 8 cm off in x, outside the
// 5 cm success radius.
void BiasedBase(const float* obs, float* a) {
  for (int k = 0; k < 2; ++k) a[k] = std::clamp(5.0f * obs[2 + k], -1.0f, 1.0f);
  a[0] = std::clamp(a[0] + 0.4f, -1.0f, 1.0f);
}

struct Outcome {
  double mean_return = 0, success = 0;
};

// Episodes of the agent (mean actions; with `residual`, on top of BiasedBase) from their own
// seeds.
Outcome Evaluate(OffPolicyAgent& agent, bool residual, int episodes) {
  Outcome out;
  core::Rng rng(99);
  for (int e = 0; e < episodes; ++e) {
    PointReach env;
    env.Reset(rng);
    float obs[PointReach::kObs], base[2], a[2];
    for (int t = 0; t < PointReach::kHorizon; ++t) {
      env.Obs(obs);
      BiasedBase(obs, base);
      agent.Act(obs, residual ? base : nullptr, false, rng, a);
      out.mean_return += env.Step(a);
    }
    out.success += env.Distance() < 0.05;
  }
  out.mean_return /= episodes;
  out.success /= episodes;
  return out;
}

// Trains for `episodes`, one update per step after the first `warmup` steps (critic only for the
// first `critic_only` updates).
void Train(OffPolicyAgent& agent, bool residual, int episodes, int warmup, int critic_only,
           uint64_t seed) {
  ReplayBuffer buffer(PointReach::kObs, PointReach::kAction, 100000);
  core::Rng env_rng(seed, 1), act_rng(seed, 2), update_rng(seed, 3);
  int64_t steps = 0, updates = 0;
  for (int e = 0; e < episodes; ++e) {
    PointReach env;
    env.Reset(env_rng);
    float obs[4], base[2], a[2], next[4], next_base[2];
    env.Obs(obs);
    BiasedBase(obs, base);
    for (int t = 0; t < PointReach::kHorizon; ++t) {
      agent.Act(obs, residual ? base : nullptr, true, act_rng, a);
      const float r = env.Step(a);
      env.Obs(next);
      BiasedBase(next, next_base);
      buffer.Add(obs, base, a, r, next, next_base, false);
      std::copy_n(next, 4, obs);
      std::copy_n(next_base, 2, base);
      if (++steps > warmup) agent.Update(buffer, update_rng, ++updates > critic_only);
    }
  }
}

OffPolicyOptions Small(const std::string& algorithm, bool residual) {
  OffPolicyOptions o;
  o.algorithm = algorithm;
  o.hidden = 64;
  o.batch = 64;
  o.learning_rate = 1e-3;
  o.gamma = 0.9;
  o.tau = 0.02;
  o.residual = residual;
  o.seed = 5;
  return o;
}

TEST(OffPolicy, AZeroInitialisedResidualLeavesActionsUnchanged) {
  PinMathThreads(1);
  for (const char* algorithm : {"td3", "sac"}) {
    OffPolicyAgent agent(PointReach::kObs, PointReach::kAction, Small(algorithm, true));
    core::Rng rng(1);
    for (int i = 0; i < 20; ++i) {
      const float obs[4] = {float(rng.Normal()), float(rng.Normal()), float(rng.Normal()),
                            float(rng.Normal())};
      const float base[2] = {float(rng.Uniform(-1, 1)), float(rng.Uniform(-1, 1))};
      float a[2];
      agent.Act(obs, base, false, rng, a);
      EXPECT_EQ(a[0], base[0]) << algorithm;
      EXPECT_EQ(a[1], base[1]) << algorithm;
    }
    const torch::Tensor obs = torch::randn({8, 4}), base = torch::rand({8, 2}) * 2 - 1;
    EXPECT_TRUE(torch::equal(agent.ActBatch(obs, base), base)) << algorithm;
  }
}

// From a random actor to one that reaches the goal.
TEST(OffPolicy, Td3AndSacLearnToReach) {
  PinMathThreads(1);
  for (const char* algorithm : {"td3", "sac"}) {
    OffPolicyAgent agent(PointReach::kObs, PointReach::kAction, Small(algorithm, false));
    const Outcome before = Evaluate(agent, false, 50);
    Train(agent, false, 150, 200, 0, 3);
    const Outcome after = Evaluate(agent, false, 50);
    EXPECT_LT(before.success, 0.2) << algorithm;
    EXPECT_GT(after.success, 0.8) << algorithm << " return " << before.mean_return << " -> "
                                  << after.mean_return;
    EXPECT_GT(after.mean_return, before.mean_return + 1.0) << algorithm;
  }
}

// SAM-RL's use: a base policy that settles off target, corrected by a residual trained critic
// first. It starts exactly at the base policy's success and rises above it.
TEST(OffPolicy, AResidualCorrectsABiasedBasePolicy) {
  PinMathThreads(1);
  OffPolicyAgent agent(PointReach::kObs, PointReach::kAction, Small("td3", true));
  const Outcome base = Evaluate(agent, true, 50);
  EXPECT_EQ(base.success, 0.0);
  Train(agent, true, 120, 100, 200, 4);
  const Outcome after = Evaluate(agent, true, 50);
  EXPECT_GT(after.success, 0.8) << "return " << base.mean_return << " -> " << after.mean_return;
}

// Same seed, same agent; a saved agent loads to the same actions, and a file of another size
// is refused by name.
TEST(OffPolicy, DeterministicAndRoundTrips) {
  PinMathThreads(1);
  const auto dir = core::testing::TestDir("offpolicy_test", "roundtrip");
  OffPolicyAgent a(4, 2, Small("sac", true)), b(4, 2, Small("sac", true));
  Train(a, true, 5, 20, 10, 7);
  Train(b, true, 5, 20, 10, 7);
  const torch::Tensor obs = torch::randn({16, 4}), base = torch::rand({16, 2}) * 2 - 1;
  EXPECT_TRUE(torch::equal(a.ActBatch(obs, base), b.ActBatch(obs, base)));
  EXPECT_FALSE(torch::equal(a.ActBatch(obs, base), base));
  a.Save(dir / "agent.pt");
  OffPolicyAgent c(4, 2, Small("sac", true));
  c.Load(dir / "agent.pt");
  EXPECT_TRUE(torch::equal(a.ActBatch(obs, base), c.ActBatch(obs, base)));
  EXPECT_EQ(c.updates(), a.updates());
  OffPolicyAgent wrong(5, 2, Small("sac", true));
  try {
    wrong.Load(dir / "agent.pt");
    FAIL() << "a 4-input agent loaded into a 5-input one";
  } catch (const core::Error& e) {
    EXPECT_NE(std::string(e.what()).find("agent.pt"), std::string::npos) << e.what();
  }
  ReplayBuffer buffer(4, 2, 10);
  const float nan_obs[4] = {0, NAN, 0, 0}, ok[4] = {}, act[2] = {};
  EXPECT_THROW(buffer.Add(nan_obs, nullptr, act, 0, ok, nullptr, false), core::NumericError);
  EXPECT_EQ(buffer.size(), 0);
}

}  // namespace
}  // namespace twinforge::learn

namespace twinforge::learn {
namespace {

// Saving and loading between updates changes nothing: the next updates match step for step.
TEST(OffPolicy, ASavedAgentContinuesExactly) {
  PinMathThreads(1);
  const auto dir = core::testing::TestDir("offpolicy_test", "continue");
  for (const char* algorithm : {"td3", "sac"}) {
    OffPolicyAgent a(4, 2, Small(algorithm, true));
    Train(a, true, 3, 10, 5, 8);
    a.Save(dir / "a.pt");
    ReplayBuffer buffer(4, 2, 100);
    core::Rng fill(2);
    for (int i = 0; i < 50; ++i) {
      float o[4], b[2], act[2], n[4];
      for (float* v : {o, n})
        for (int k = 0; k < 4; ++k) v[k] = float(fill.Normal());
      for (float* v : {b, act})
        for (int k = 0; k < 2; ++k) v[k] = float(fill.Uniform(-1, 1));
      buffer.Add(o, b, act, float(fill.Uniform()), n, b, i % 7 == 0);
    }
    buffer.Save(dir / "buffer.pt");
    ReplayBuffer loaded(4, 2, 100);
    loaded.Load(dir / "buffer.pt");
    auto b = OffPolicyAgent::Open(dir / "a.pt");
    core::Rng ra(5), rb(5);
    for (int i = 0; i < 6; ++i) {
      const auto sa = a.Update(buffer, ra);
      const auto sb = b->Update(loaded, rb);
      EXPECT_EQ(sa.critic_loss, sb.critic_loss) << algorithm << " update " << i;
      EXPECT_EQ(sa.actor_loss, sb.actor_loss) << algorithm << " update " << i;
    }
  }
}

}  // namespace
}  // namespace twinforge::learn
