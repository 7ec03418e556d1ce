// SAM-RL's actor learned by imitation in the twin: a state policy (the twin's privileged state in,
// an action out) taught on the twin's scripted expert's trajectories, with noise injected into
// the actions it takes (DART, Laskey et al. 2017): the expert acts, its action is perturbed
// before the robot gets it, and the state it lands in is labelled with the expert's clean action
// there. The learner so sees states a little off the expert's path and the way back to it.
//
// Why not DAgger (the learner acts, the expert labels): the scripted expert is a sequence of steps
// and knows which one it is in only from its own progress. A learner cutting a corner (going
// straight down to the peg instead of through the point above it) leaves the expert in its first
// step while the peg is already in the hand; its labels then say "go back above the peg, open".
// Tried on the peg: the learner fell from 28% to 0-2% after one such round, the labels' loss
// rising from 0.03 to 0.16. With the expert acting, its step always fits the scene.
//
// The expert is patient here (it never gives a step up when its max_steps run out): giving up,
// it would teach the learner to move on from a state the step never reached.
//
// Each round adds `episodes` noisy expert episodes; the learner then trains on everything so far
// (`train_steps` Adam steps; cross-entropy on a discrete move, squared error of the mean in units
// of the action's per-step limits on a continuous one) and is evaluated in the twin, acting on
// its mean. The policy kept is the best evaluated, in the file format of every twinforge policy
// (`sim eval --policy`, the twin actor's `--actor-policy`).
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <vector>

#include "core/progress.h"
#include "sim/action.h"
#include "sim/env.h"
#include "sim/expert.h"
#include "sim/task.h"

namespace twinforge::learn {

struct ImitationOptions {
  int rounds = 4;
  int episodes = 100;      // expert episodes per round
  int train_steps = 2000;  // Adam steps after each round, on all the data so far
  // Noise on the actions taken (the labels stay clean): continuous, Gaussian with this standard
  // deviation in units of the per-step limits; discrete, the probability of a random move.
  double noise = 0.02;
  // iterations > 0: the expert plans each free move by this many iLQR iterations through the
  // twin's own dynamics and follows the plan (sim::ScriptedExpert::set_planning): the actor then
  // imitates trajectories optimized in the twin, SAM-RL's route. 0: the script's straight moves.
  sim::PlanOptions plan;
  int batch = 256;
  int hidden = 256;
  double learning_rate = 1e-3;
  // The state's normalization is fitted on round 0's states; a component the expert holds nearly
  // still (a top-down tool's tilt) gets at least this standard deviation, so the learner's first
  // small tilt is not scaled into an input it never saw.
  double std_floor = 0.01;
  int level = 1;  // randomization level of every round and of the evaluation
  int eval_episodes = 100;
  uint64_t eval_seed = 9000;
  uint64_t seed = 1;
  int threads = 2;  // episodes side by side (the result does not depend on it)
  template <class A>
  void Serialize(A& a) {
    a("rounds", rounds);
    a("episodes", episodes);
    a("train_steps", train_steps);
    a("noise", noise);
    a("optimize_moves", plan.iterations);
    a("plan_stretch", plan.stretch);
    a("plan_along_path", plan.along_path);
    a("plan_end_speed_weight", plan.end_speed_weight);
    a("batch", batch);
    a("hidden", hidden);
    a("learning_rate", learning_rate);
    a("std_floor", std_floor);
    a("level", level);
    a("eval_episodes", eval_episodes);
    a("eval_seed", eval_seed);
    a("seed", seed);
    a("threads", threads);
    a.Require(rounds > 0 && episodes > 0, "rounds", "positive rounds of positive episodes");
    a.Require(train_steps > 0 && batch > 0 && hidden > 0 && threads > 0, "train_steps",
              "positive step, batch, layer and thread counts");
    a.Require(noise >= 0, "noise", "non-negative noise");
    a.Require(plan.iterations >= 0, "optimize_moves", "a non-negative iteration count");
    a.Require(plan.stretch >= 1, "plan_stretch", "a stretch of at least 1");
    a.Require(plan.end_speed_weight >= 0, "plan_end_speed_weight", "a non-negative weight");
    a.Require(learning_rate > 0 && std_floor > 0, "learning_rate", "positive rate and floor");
    a.Require(level >= 0 && level <= 3, "level", "a randomization level 0..3");
    a.Require(eval_episodes >= 0, "eval_episodes", "a non-negative count");
  }
};

struct ImitationRound {
  int round = 0;
  int episodes = 0;       // run this round
  int successes = 0;      // of them, by the noisy expert
  sim::PlanCounts plans;  // plan.iterations > 0: the round's plans
  long steps = 0;         // labelled steps gathered so far (all rounds)
  double loss = 0;        // mean training loss over the round's last 100 steps
  double learner = -1;    // the learner's success in the twin afterwards (-1: not evaluated)
  double seconds = 0;     // since the start
};

struct ImitationReport {
  std::vector<ImitationRound> rounds;
  int best_round = 0;  // whose weights were written
  double seconds = 0;
  std::filesystem::path curve;  // CSV, one row per round
};

// Teaches a state policy for `task` on its scripted expert's noisy episodes and writes the best one
// (by success in the twin; the last when eval_episodes is 0) to `out`, the curve beside it.
// `progress` counts the expert's episodes (rounds x episodes).
ImitationReport TrainImitation(std::shared_ptr<const sim::Task> task,
                               const std::filesystem::path& out, const ImitationOptions& options,
                               core::Progress* progress = nullptr);

// A state policy's action for an env as it is now: its most likely move, or its mean.
using StateActor = std::function<sim::Action(const sim::Env&)>;
// The state policy in `file` as an actor for `task`. Throws Error naming the file when it sees
// points (a student) or does not fit the task's state and actions.
StateActor LoadStateActor(const std::filesystem::path& file, const sim::Task& task);

}  // namespace twinforge::learn
