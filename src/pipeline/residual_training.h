// SAM-RL's last step: a residual policy trained on reality (the proxy reality, or a robot whose
// oracle tells success) on top of a base actor (a point-cloud policy, or the twin actor). The
// residual starts at zero (the robot first runs the base unchanged), its critics train alone over
// the first episodes, then actor and critics together, with TD3 or SAC on the sparse success
// reward. Without residual mode the same loop trains TD3 or SAC from scratch on the same
// observations, as baselines.
//
// Episode e is reset with seed MixSeed(seed, e). After every episode the agent, its replay
// buffer and the counters are saved beside `out`: a killed run resumes after the last whole
// episode and goes on exactly as an uninterrupted one would.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>

#include "core/progress.h"
#include "learn/offpolicy.h"
#include "reality/robot.h"
#include "sim/task.h"

namespace twinforge::pipeline {

struct ResidualTrainOptions {
  int episodes = 50;  // episodes on the robot
  int level = 1;      // randomization level asked of the robot's resets
  uint64_t seed = 6000;
  int critic_episodes = 10;  // the critics train alone over these first episodes
  int updates_per_step = 2;  // gradient steps per recorded step, taken after each episode
  int scene_points = 2048, arm_points = 512;
  bool sample = false;  // the base policy samples its moves (else the most likely)
  // Residual mode (off: the agent acts alone, from scratch, on the same observations: the TD3 and
  // SAC baselines). By default it corrects the translation only, a fifth of a
  // step at most, with 0.03-step exploration noise: on the drawer, 0.1-step noise on every
  // component (rotation drifting ~1 degree a step, a grip held a few percent open) took the
  // base policy from 44% to 2%, so nothing was left to learn from.
  learn::OffPolicyOptions agent = DefaultAgent();
  static learn::OffPolicyOptions DefaultAgent() {
    learn::OffPolicyOptions o;
    o.residual = true;
    o.residual_dims = 3;
    o.residual_scale = 0.2;
    o.exploration_noise = 0.03;
    o.residual_penalty = 0.1;
    o.gamma = 0.98;
    return o;
  }
  template <class A>
  void Serialize(A& a) {
    a("episodes", episodes);
    a("level", level);
    a("seed", seed);
    a("critic_episodes", critic_episodes);
    a("updates_per_step", updates_per_step);
    a("scene_points", scene_points);
    a("arm_points", arm_points);
    a("sample", sample);
    a("agent", agent);
    a.Require(episodes > 0, "episodes", "at least one episode");
    a.Require(level >= 0 && level <= 3, "level", "a level in 0..3");
    a.Require(critic_episodes >= 0 && updates_per_step >= 0, "critic_episodes",
              "non-negative critic episodes and updates per step");
  }
};

struct ResidualTrainReport {
  int episodes = 0, successes = 0;  // over all episodes, resumed ones included
  int resumed_from = 0;             // episodes read back from the checkpoint
  int64_t transitions = 0, updates = 0;
  std::filesystem::path residual, curve_csv;
  double seconds = 0;
};

// Trains the residual on `base` and writes it to `out`, with `out`.buffer, `out`.state.json and
// `out`.curve.csv beside it. `fresh` discards a checkpoint. The base is begun with each episode's
// seed; it should say "done" when the robot's oracle reports success.
struct ResidualBase;
ResidualTrainReport TrainResidualOnReality(reality::Robot& robot, const ResidualBase& base,
                                           const sim::TaskSpec& task,
                                           const ResidualTrainOptions& options,
                                           const std::filesystem::path& out, bool fresh,
                                           core::Progress* progress = nullptr);
// The same on `base_policy`, a point-cloud policy file (options' points and sampling apply).
ResidualTrainReport TrainResidualOnReality(reality::Robot& robot,
                                           const std::filesystem::path& base_policy,
                                           const sim::TaskSpec& task,
                                           const ResidualTrainOptions& options,
                                           const std::filesystem::path& out, bool fresh,
                                           core::Progress* progress = nullptr);

}  // namespace twinforge::pipeline
