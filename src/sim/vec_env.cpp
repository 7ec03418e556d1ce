#include "sim/vec_env.h"

#include "core/error.h"

namespace twinforge::sim {

VecEnv::VecEnv(std::shared_ptr<const Task> task, const VecEnvOptions& options)
    : pool_(options.threads), level_(options.level) {
  if (options.num_envs <= 0)
    throw core::ConfigError("", "num_envs", "expected a positive number of environments");
  for (int i = 0; i < options.num_envs; ++i) {
    envs_.push_back(std::make_unique<Env>(task, i));
    episode_rngs_.emplace_back(options.seed, static_cast<uint64_t>(i));
  }
  state_dim_ = envs_[0]->state_dim();
  const std::size_t n = envs_.size();
  states_.assign(n * state_dim_, 0.0f);
  proprio_.assign(n * kProprioDim, 0.0f);
  rewards_.assign(n, 0.0f);
  dones_.assign(n, 0);
  successes_.assign(n, 0);
  episode_success_.assign(n, 0);
  succeeded_.assign(n, 0);
  episode_length_.assign(n, 0);
  // One function object for the whole run: Step allocates nothing.
  step_fn_ = [this](int64_t i) {
    Env& env = *envs_[i];
    const StepResult r = env.Step(actions_[i]);
    rewards_[i] = r.reward;
    successes_[i] = r.success;
    succeeded_[i] |= r.success;
    dones_[i] = r.done;
    episode_success_[i] = 0;
    episode_length_[i] = 0;
    if (r.done) {
      episode_success_[i] = succeeded_[i] && !r.unstable;
      episode_length_[i] = env.steps();
      ResetEnv(static_cast<int>(i));
    }
    WriteObservation(static_cast<int>(i));
  };
}

void VecEnv::ResetEnv(int i) {
  envs_[i]->Reset(episode_rngs_[i].Bits(), level_);
  succeeded_[i] = 0;
}

void VecEnv::WriteObservation(int i) {
  envs_[i]->State(states_.data() + static_cast<std::size_t>(i) * state_dim_);
  envs_[i]->Proprio(proprio_.data() + static_cast<std::size_t>(i) * kProprioDim);
}

void VecEnv::Reset() {
  pool_.ParallelFor(num_envs(), [this](int64_t i) {
    ResetEnv(static_cast<int>(i));
    WriteObservation(static_cast<int>(i));
    dones_[i] = 0;
  });
}

void VecEnv::Reset(uint64_t seed) {
  for (int i = 0; i < num_envs(); ++i) episode_rngs_[i] = core::Rng(seed, static_cast<uint64_t>(i));
  Reset();
}

void VecEnv::Step(const Action* actions) {
  actions_ = actions;
  pool_.ParallelFor(num_envs(), step_fn_);
  actions_ = nullptr;
}

}  // namespace twinforge::sim
