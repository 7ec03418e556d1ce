// A policy's success rate in the sim, and inverse distillation.
//
// A policy's success rate in the sim (a twin or a hand-made task scene): N seeded episodes at a
// randomization level, the policy acting greedily on the clouds a camera placed like the real
// one sees (ray-cast depth with the depth-noise model, arm points from forward kinematics).
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <ostream>
#include <vector>

#include "core/progress.h"
#include "sim/task.h"

namespace twinforge::learn {

struct PolicyEvalOptions {
  int episodes = 50;
  int level = 1;
  uint64_t seed = 1000;  // episode i is reset with MixSeed(seed, i), as `sim expert`'s
  int threads = 1;       // envs stepped in parallel (the outcome does not depend on it)
  int scene_points = 2048, arm_points = 512;  // as `demos record` stores them
  // Greedy takes the most likely move (or the mean); sampling draws from the policy's
  // distribution sharpened or widened by `temperature` (inverse distillation's noise).
  bool sample = false;
  double temperature = 1.0;
};

struct PolicyEvalReport {
  int episodes = 0, successes = 0;
  double success_rate() const { return episodes ? double(successes) / episodes : 0.0; }
  std::vector<int> steps;  // per episode: control steps to success, -1 on failure
  double seconds = 0;
};

// Episode `episode` of an evaluation (reset as EvaluatePolicy resets it), one JSON object per
// step: {"step", "action", "state" (privileged), "reward"}, then {"success", "steps"}. For
// seeing where a policy goes wrong.
void TracePolicyEpisode(const std::filesystem::path& policy, std::shared_ptr<const sim::Task> task,
                        const PolicyEvalOptions& options, int64_t episode, std::ostream& out);

// Throws Error naming the policy file when its inputs or actions do not fit the task.
PolicyEvalReport EvaluatePolicy(const std::filesystem::path& policy,
                                std::shared_ptr<const sim::Task> task,
                                const PolicyEvalOptions& options);

// RialTo's inverse distillation: the policy learned from the real demos is rolled out in the twin
// (with noise: options.sample), and only its successful episodes are kept, with privileged state,
// as demos for RL. Episodes run in rounds of `round` so the demos kept do not depend on the
// thread count.
struct InverseDistillOptions {
  PolicyEvalOptions rollout;  // episodes: the budget of attempts
  int successes = 15;         // stop once this many are kept
  int round = 16;
};
struct InverseDistillReport {
  int attempts = 0, successes = 0;
  double success_rate() const { return attempts ? double(successes) / attempts : 0.0; }
  double seconds = 0;
};
// Writes the kept episodes to `out` (which must not exist), then returns the counts.
InverseDistillReport InverseDistill(const std::filesystem::path& policy,
                                    std::shared_ptr<const sim::Task> task,
                                    const InverseDistillOptions& options,
                                    const std::filesystem::path& out,
                                    core::Progress* progress = nullptr);

// Sim demos for RL when the real-demo policy never succeeds in the twin (RialTo's fallback: a
// person demonstrates in the twin): the twin's scripted operator, which reads the twin's state,
// runs `options.rollout.episodes` seeded episodes at most, and its first `options.successes`
// successes are kept as InverseDistill keeps the policy's. Same file layout, without clouds.
InverseDistillReport ExpertDemos(std::shared_ptr<const sim::Task> task,
                                 const InverseDistillOptions& options,
                                 const std::filesystem::path& out,
                                 core::Progress* progress = nullptr);

}  // namespace twinforge::learn
