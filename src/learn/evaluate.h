// A policy's success rate in the sim (a twin or a hand-made task scene): N seeded episodes at a
// randomization level, the policy acting greedily on the clouds a camera placed like the real
// one sees (ray-cast depth with the depth-noise model, arm points from forward kinematics).
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <vector>

#include "sim/task.h"

namespace twinforge::learn {

struct PolicyEvalOptions {
  int episodes = 50;
  int level = 1;
  uint64_t seed = 1000;  // episode i is reset with MixSeed(seed, i), as `sim expert`'s
  int threads = 1;       // envs stepped in parallel (the outcome does not depend on it)
  int scene_points = 2048, arm_points = 512;  // as `demos record` stores them
};

struct PolicyEvalReport {
  int episodes = 0, successes = 0;
  double success_rate() const { return episodes ? double(successes) / episodes : 0.0; }
  std::vector<int> steps;  // per episode: control steps to success, -1 on failure
  double seconds = 0;
};

// Throws Error naming the policy file when its inputs or actions do not fit the task.
PolicyEvalReport EvaluatePolicy(const std::filesystem::path& policy,
                                std::shared_ptr<const sim::Task> task,
                                const PolicyEvalOptions& options);

}  // namespace twinforge::learn
