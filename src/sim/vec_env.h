// N environments of one task stepped together over a fixed thread pool.
//
// Buffers are batch-shaped and allocated once; stepping allocates nothing. Env i draws the seed of
// each of its episodes from its own generator, seeded from (seed, i), so results do not depend
// on the thread count. A finished env is reset at once (auto-reset): its row then holds the first
// observation of the next episode, and `done` tells the learner the previous one ended.
#pragma once

#include <memory>
#include <vector>

#include "core/rng.h"
#include "core/thread_pool.h"
#include "sim/env.h"

namespace twinforge::sim {

struct VecEnvOptions {
  int num_envs = 8;
  int threads = 1;
  uint64_t seed = 0;
  int level = 1;
};

class VecEnv {
 public:
  VecEnv(std::shared_ptr<const Task> task, const VecEnvOptions& options);

  // Resets every env (new episodes) and fills the observation buffers.
  void Reset();
  // Re-seeds env i's episode generator from (seed, i), then resets: a learner that resets with
  // a seed drawn from its own counters needs to save nothing of the VecEnv to resume exactly.
  void Reset(uint64_t seed);
  // Steps env i with actions[i] for all i (num_envs actions).
  void Step(const Action* actions);

  int num_envs() const { return static_cast<int>(envs_.size()); }
  int state_dim() const { return state_dim_; }
  // [num_envs, state_dim] privileged state and [num_envs, kProprioDim] proprioception.
  const float* states() const { return states_.data(); }
  const float* proprio() const { return proprio_.data(); }
  // Per env, for the step just taken.
  const float* rewards() const { return rewards_.data(); }
  const uint8_t* dones() const { return dones_.data(); }
  const uint8_t* successes() const { return successes_.data(); }
  // For envs that finished on the last step: whether the task succeeded at any step of that
  // episode, and its length.
  const uint8_t* episode_success() const { return episode_success_.data(); }
  const int* episode_length() const { return episode_length_.data(); }

  Env& env(int i) { return *envs_[i]; }
  const Env& env(int i) const { return *envs_[i]; }
  int threads() const { return pool_.size(); }

 private:
  void ResetEnv(int i);
  void WriteObservation(int i);

  std::vector<std::unique_ptr<Env>> envs_;
  std::vector<core::Rng> episode_rngs_;
  core::ThreadPool pool_;
  int level_;
  int state_dim_;
  std::vector<float> states_, proprio_, rewards_;
  std::vector<uint8_t> dones_, successes_, episode_success_, succeeded_;
  std::vector<int> episode_length_;
  const Action* actions_ = nullptr;
  std::function<void(int64_t)> step_fn_;
};

}  // namespace twinforge::sim
