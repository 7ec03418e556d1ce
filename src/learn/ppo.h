// RialTo's RL fine-tuning: PPO on privileged state over the VecEnv, with the task's sparse success
// reward and randomization, plus a BC loss on the sim demos from inverse distillation.
//
// One rollout is one episode per env (the task's horizon), every env reset at the start of each
// iteration from a seed drawn from (seed, iteration). Action sampling, minibatch order and demo
// batches draw from generators seeded the same way, so a checkpoint needs only the networks, the
// optimizer, the normalizer and the counters to resume step for step.
#pragma once

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>

#include "core/progress.h"
#include "sim/task.h"

namespace twinforge::learn {

struct PpoOptions {
  int num_envs = 64;
  int threads = 2;  // envs stepped in parallel; results do not depend on it
  int level = 1;    // randomization level of the training episodes
  uint64_t seed = 1;
  int hidden = 256;  // policy and value MLPs: two layers this wide
  // SB3's PPO defaults, as RialTo used them.
  double learning_rate = 3e-4, gamma = 0.99, lambda = 0.95, clip = 0.2;
  int epochs = 10;
  int minibatches = 4;  // per epoch
  double max_grad_norm = 0.5, value_coef = 0.5, entropy_coef = 0.0;
  // BC on the sim demos: cross-entropy (or Gaussian log-likelihood) of a fresh batch of demo
  // steps at every minibatch, weighted by bc_coef. No demos: PPO from scratch.
  double bc_coef = 0.1;
  int bc_batch = 32;
  // BC alone before PPO starts: bc_pretrain_steps Adam steps of bc_pretrain_batch demo steps, the
  // observation normalizer started from the demos' states. PPO then fine-tunes an imitation of the
  // demos rather than a random policy; for the first critic_warmup iterations only the value
  // network trains, so the advantages the policy first sees come from a critic fitted to it.
  int bc_pretrain_steps = 0;
  int bc_pretrain_batch = 256;
  int critic_warmup = 0;
  // Or PPO fine-tunes a state policy trained elsewhere (`train imitate`'s actor), from its
  // weights and its observation normalization, which stays fixed: the weights were fitted to it
  // (imitation floors a still component's spread that PPO's running statistics would shrink).
  // Its continuous actions are sampled with `init_std` times the per-step limits at first (the
  // imitation's own noise; PPO's default start, half the limits, would undo a fine policy).
  std::string init_policy;
  double init_std = 0.02;
  // Stopping: success over eval_episodes (their own seeds) every eval_every iterations reaching
  // target_success, or a budget (0: none). The policy is evaluated as PPO trains it, sampling its
  // moves (eval_sample); greedy (the most likely move) gets stuck in loops of near-tied moves
  // early on and trails it (open drawer: 38-50% greedy at 75-80% sampled).
  double target_success = 0.9;
  bool eval_sample = true;
  // 100 episodes: at 90% the estimate's standard error is 3 points (with 50, a policy at 81% on
  // 100 fresh episodes passed a 0.9 target once).
  int eval_every = 10;
  int eval_episodes = 100;
  uint64_t eval_seed = 7000;
  // Budgets: iterations by default, so a run is the same on any machine, thread count or load
  // (a wall-clock budget stops where the machine's speed says).
  double max_seconds = 0;
  int64_t max_env_steps = 0;
  int max_iterations = 200;
  template <class A>
  void Serialize(A& a) {
    a("num_envs", num_envs);
    a("threads", threads);
    a("level", level);
    a("seed", seed);
    a("hidden", hidden);
    a("learning_rate", learning_rate);
    a("gamma", gamma);
    a("lambda", lambda);
    a("clip", clip);
    a("epochs", epochs);
    a("minibatches", minibatches);
    a("max_grad_norm", max_grad_norm);
    a("value_coef", value_coef);
    a("entropy_coef", entropy_coef);
    a("bc_coef", bc_coef);
    a("bc_batch", bc_batch);
    a("bc_pretrain_steps", bc_pretrain_steps);
    a("bc_pretrain_batch", bc_pretrain_batch);
    a("critic_warmup", critic_warmup);
    a("init_policy", init_policy);
    a("init_std", init_std);
    a("target_success", target_success);
    a("eval_sample", eval_sample);
    a("eval_every", eval_every);
    a("eval_episodes", eval_episodes);
    a("eval_seed", eval_seed);
    a("max_seconds", max_seconds);
    a("max_env_steps", max_env_steps);
    a("max_iterations", max_iterations);
    a.Require(num_envs > 0 && threads > 0 && hidden > 0, "num_envs",
              "positive env, thread and layer counts");
    a.Require(epochs > 0 && minibatches > 0 && bc_batch > 0, "epochs",
              "positive epoch, minibatch and batch counts");
    a.Require(learning_rate > 0 && clip > 0, "learning_rate", "a positive rate and clip");
    a.Require(eval_every > 0 && eval_episodes > 0, "eval_every", "positive evaluation counts");
    a.Require(bc_pretrain_steps >= 0 && bc_pretrain_batch > 0 && critic_warmup >= 0,
              "bc_pretrain_steps", "non-negative pretraining and warm-up counts");
    a.Require(init_policy.empty() || bc_pretrain_steps == 0, "init_policy",
              "either a policy to start from or BC pretraining, not both");
    a.Require(init_std > 0, "init_std", "a positive standard deviation");
  }
};

struct PpoReport {
  int iterations = 0;
  int64_t env_steps = 0;
  double seconds = 0;  // wall-clock over every session of the run
  double best_eval_success = 0;
  int best_iteration = 0;           // whose weights are in `out`
  int resumed_from = 0;             // iteration of the checkpoint this session started from
  std::string stopped_by;           // target | seconds | env_steps | iterations
  double update_samples_per_s = 0;  // median over this session's iterations
  // The same against this machine's matmul peak, measured at the end of the session (0: no
  // update ran this session).
  double matmul_peak_gflops = 0, update_share_of_matmul_peak = 0;
  int demo_steps = 0;
  double pretrain_bc_loss = NAN;       // BC pretraining's last loss (NaN: none this session)
  double pretrain_eval_success = NAN;  // success of the pretrained (or --init) policy, before PPO
  std::filesystem::path curve_csv, curve_svg, checkpoint;
};

// What TrainPpo does with a checkpoint it finds.
enum class CheckpointMode {
  kResume,             // resume it; throw Error naming it if it was made from other inputs
  kResumeOrStartOver,  // resume it if it was made from the same inputs, else start over
  kStartOver,          // discard it
};

// Trains a state policy for `task` and writes the best-evaluated weights to `out`, the curve
// (CSV and SVG) beside it and a checkpoint `<out>.ckpt` after every iteration. A checkpoint's
// inputs are the task (its spec and compiled model, so a twin rebuilt under the same path is
// another task), the demos' content and the options (budgets and threads aside, and evaluation,
// which changes nothing of training); `checkpoint` says what happens to one that exists.
// `demos` empty: no BC loss.
PpoReport TrainPpo(std::shared_ptr<const sim::Task> task, const std::filesystem::path& demos,
                   const std::filesystem::path& out, const PpoOptions& options,
                   CheckpointMode checkpoint = CheckpointMode::kResume,
                   core::Progress* progress = nullptr);

}  // namespace twinforge::learn
