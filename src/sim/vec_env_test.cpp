#include "sim/vec_env.h"

#include <gtest/gtest.h>

#include <cstring>

#include "core/error.h"

namespace twinforge::sim {
namespace {

std::shared_ptr<const Task> DrawerTask() {
  static auto task = std::make_shared<const Task>(LoadTaskSpec("open_drawer"));
  return task;
}

// Runs `steps` steps of random discrete actions (drawn from a fixed generator) and returns every
// observation, reward and done flag seen.
std::vector<float> Rollout(int threads, int steps) {
  VecEnv vec(DrawerTask(), {.num_envs = 6, .threads = threads, .seed = 11, .level = 3});
  vec.Reset();
  core::Rng policy(5);
  std::vector<Action> actions(vec.num_envs());
  std::vector<float> trace;
  for (int t = 0; t < steps; ++t) {
    for (auto& a : actions) a = Action::Discrete(static_cast<int>(policy.Index(kDiscreteActions)));
    vec.Step(actions.data());
    trace.insert(trace.end(), vec.states(), vec.states() + vec.num_envs() * vec.state_dim());
    for (int i = 0; i < vec.num_envs(); ++i) {
      trace.push_back(vec.rewards()[i]);
      trace.push_back(vec.dones()[i]);
    }
  }
  return trace;
}

TEST(VecEnv, IdenticalResultsForOneAndTwoThreads) {
  // 100 steps crosses the 80-step horizon: auto-reset and level-3 pushes are included.
  const auto one = Rollout(1, 100), two = Rollout(2, 100);
  ASSERT_EQ(one.size(), two.size());
  EXPECT_EQ(std::memcmp(one.data(), two.data(), one.size() * sizeof(float)), 0);
}

TEST(VecEnv, AutoResetStartsANewEpisodeAtTheHorizon) {
  VecEnv vec(DrawerTask(), {.num_envs = 2, .threads = 1, .seed = 1, .level = 1});
  vec.Reset();
  std::vector<Action> hold(2, Action::Discrete(12));
  const int horizon = DrawerTask()->spec().horizon;
  for (int t = 0; t < horizon - 1; ++t) {
    vec.Step(hold.data());
    ASSERT_FALSE(vec.dones()[0]);
  }
  vec.Step(hold.data());
  EXPECT_TRUE(vec.dones()[0]);
  EXPECT_EQ(vec.episode_length()[0], horizon);
  EXPECT_FALSE(vec.episode_success()[0]);  // holding still never opens the drawer
  EXPECT_EQ(vec.env(0).steps(), 0);        // already reset
}

TEST(Env, ResetRestoresStateBitForBit) {
  Env env(DrawerTask());
  auto run = [&] {
    env.Reset(42, 3);
    std::vector<double> qpos;
    for (int t = 0; t < 30; ++t) env.Step(Action::Discrete(t % 12));
    qpos.assign(env.data()->qpos, env.data()->qpos + env.model()->nq);
    qpos.insert(qpos.end(), env.data()->qvel, env.data()->qvel + env.model()->nv);
    qpos.push_back(env.data()->time);
    return qpos;
  };
  const auto first = run();
  // A different episode in between changes model and data (distractors, pushes, poses).
  env.Reset(7, 3);
  for (int t = 0; t < 50; ++t) env.Step(Action::Discrete((t * 5) % 14));
  const auto second = run();
  ASSERT_EQ(first.size(), second.size());
  EXPECT_EQ(std::memcmp(first.data(), second.data(), first.size() * sizeof(double)), 0);
}

TEST(Env, LevelsChangeTheScene) {
  Env env(DrawerTask());
  std::vector<float> nominal(env.state_dim()), moved(env.state_dim());
  env.Reset(3, 0);
  env.State(nominal.data());
  env.Reset(3, 1);
  env.State(moved.data());
  // The chest (first object) moved at level 1.
  EXPECT_GT(std::abs(nominal[kProprioDim] - moved[kProprioDim]) +
                std::abs(nominal[kProprioDim + 1] - moved[kProprioDim + 1]),
            1e-4);
  // Level 2 places distractors on the table (mocap bodies, parked far away otherwise).
  env.Reset(3, 2);
  int on_table = 0;
  for (int i = 0; i < env.model()->nmocap; ++i) on_table += env.data()->mocap_pos[3 * i + 2] > -1;
  EXPECT_GE(on_table, 1);
}

TEST(Env, NanActionIsRejected) {
  Env env(DrawerTask());
  env.Reset(0, 0);
  auto bad = Action::Continuous({0, std::nan(""), 0, 0, 0, 0, 0});
  EXPECT_THROW(env.Step(bad), core::NumericError);
}

}  // namespace
}  // namespace twinforge::sim
