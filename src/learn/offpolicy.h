// Off-policy actor-critic on continuous actions in [-1, 1]^d: TD3 (Fujimoto et al. 2018) and SAC
// (Haarnoja et al. 2018, with a learned temperature), over a replay buffer.
//
// SAM-RL's residual mode: the actor also sees a base policy's action and outputs a bounded delta,
// action = clip(base + residual_scale * tanh(u), -1, 1), and the critics see the base action too.
// The actor's last layer starts at zero, so an untrained residual leaves the base policy's
// actions exactly unchanged; `Update(..., false)` trains the critics alone first (their target
// networks still follow them).
//
// All noise (exploration, TD3's target smoothing, SAC's reparameterization, minibatches) is drawn
// from core::Rng generators the caller owns: a seed gives the same run on any thread count.
//
// Includes <torch/torch.h>: include it only from learn's .cpp files and tests.
#pragma once

#include <torch/torch.h>

#include <cstdint>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/config.h"
#include "core/rng.h"

namespace twinforge::learn {

struct OffPolicyOptions {
  std::string algorithm = "td3";  // "td3" or "sac"
  int hidden = 256;               // actor and critics: two ReLU layers this wide
  double learning_rate = 3e-4, gamma = 0.99, tau = 0.005;
  int batch = 256;
  // TD3: the actor and the targets move every policy_delay critic steps; target actions are
  // smoothed with clipped noise; exploration adds Gaussian noise of this standard deviation.
  int policy_delay = 2;
  double target_noise = 0.2, noise_clip = 0.5, exploration_noise = 0.1;
  // SAC: the temperature starts here and is tuned toward an entropy of -(corrected components),
  // measured on tanh(u) before residual_scale.
  double initial_alpha = 0.1;
  bool learn_alpha = true;
  // Residual mode, the largest delta it may add (per component, in action units), and a penalty
  // on the delta's mean square in the actor's loss: where the critic sees no gain, the residual
  // stays near zero instead of drifting.
  bool residual = false;
  double residual_scale = 0.5;
  double residual_penalty = 0.0;
  // How many leading action components the residual changes (0: all); the others are the base's.
  // For an end-effector action, 3 corrects the translation and leaves rotation and gripper alone.
  int residual_dims = 0;
  uint64_t seed = 1;  // network initialization
  template <class A>
  void Serialize(A& a) {
    a("algorithm", algorithm);
    a("hidden", hidden);
    a("learning_rate", learning_rate);
    a("gamma", gamma);
    a("tau", tau);
    a("batch", batch);
    a("policy_delay", policy_delay);
    a("target_noise", target_noise);
    a("noise_clip", noise_clip);
    a("exploration_noise", exploration_noise);
    a("initial_alpha", initial_alpha);
    a("learn_alpha", learn_alpha);
    a("residual", residual);
    a("residual_scale", residual_scale);
    a("residual_penalty", residual_penalty);
    a("residual_dims", residual_dims);
    a("seed", seed);
    a.Require(algorithm == "td3" || algorithm == "sac", "algorithm", "td3 or sac");
    a.Require(hidden > 0 && batch > 0 && policy_delay > 0, "hidden",
              "positive hidden, batch and policy_delay");
    a.Require(learning_rate > 0 && gamma >= 0 && gamma < 1 && tau > 0 && tau <= 1, "learning_rate",
              "a positive learning rate, gamma in [0, 1), tau in (0, 1]");
    a.Require(initial_alpha > 0, "initial_alpha", "a positive temperature");
    a.Require(residual_scale > 0 && residual_scale <= 2, "residual_scale", "a value in (0, 2]");
    a.Require(residual_penalty >= 0, "residual_penalty", "a non-negative weight");
    a.Require(residual_dims >= 0, "residual_dims", "0 (all) or a number of components");
  }
};

// Transitions (obs, base action, action, reward, next obs, next base action, terminal) in flat
// arrays; the oldest are overwritten once `capacity` is reached. `terminal` marks an episode
// that ended by itself (no bootstrap), not one cut by the horizon.
class ReplayBuffer {
 public:
  ReplayBuffer(int obs_dim, int action_dim, int64_t capacity);
  // Throws NumericError naming the field when a value is NaN or infinite.
  void Add(const float* obs, const float* base, const float* action, float reward,
           const float* next_obs, const float* next_base, bool terminal);
  int64_t size() const { return size_; }
  int obs_dim() const { return obs_dim_; }
  int action_dim() const { return action_dim_; }

  struct Batch {
    torch::Tensor obs, base, action, reward, next_obs, next_base, terminal;
  };
  // n transitions drawn uniformly with replacement.
  Batch Sample(int n, core::Rng& rng) const;

  // The transitions as one LibTorch archive (temporary name, then renamed), and back; Load
  // throws naming the file when its sizes differ.
  void Save(const std::filesystem::path& path);
  void Load(const std::filesystem::path& path);

 private:
  struct Field {
    const char* name;
    std::vector<float>* data;
    int width;
  };
  std::vector<Field> Fields();  // every per-transition array, for saving and loading

  int obs_dim_, action_dim_;
  int64_t capacity_, size_ = 0, next_ = 0;
  std::vector<float> obs_, base_, action_, reward_, next_obs_, next_base_, terminal_;
};

struct OffPolicyStats {
  double critic_loss = 0, actor_loss = 0, q = 0, alpha = 0;
  bool actor_updated = false;
};

class OffPolicyAgent {
 public:
  OffPolicyAgent(int obs_dim, int action_dim, const OffPolicyOptions& options);

  // The action for one observation (`base` is read in residual mode only and may be null
  // otherwise): the actor's mean, or with `explore` TD3's Gaussian noise / a SAC sample.
  void Act(const float* obs, const float* base, bool explore, core::Rng& rng, float* action);
  // The same for a batch [B, obs_dim] (+ [B, action_dim]), without exploration.
  torch::Tensor ActBatch(const torch::Tensor& obs, const torch::Tensor& base);

  // One critic step on a sampled batch; with `train_actor`, also the actor (TD3: every
  // policy_delay-th call), SAC's temperature and the target networks.
  OffPolicyStats Update(const ReplayBuffer& buffer, core::Rng& rng, bool train_actor = true);

  // Networks, optimizers and counters in one LibTorch archive (written to a temporary name and
  // renamed); Load throws naming the file when it does not fit these sizes and options.
  void Save(const std::filesystem::path& path);
  void Load(const std::filesystem::path& path);
  // An agent built with the sizes and options stored in `path`, then loaded.
  static std::unique_ptr<OffPolicyAgent> Open(const std::filesystem::path& path);

  int obs_dim() const { return obs_dim_; }
  int action_dim() const { return action_dim_; }
  int64_t updates() const { return updates_; }
  // Free-form facts saved with the agent (a residual's trainer records its base policy here).
  nlohmann::json& info() { return info_; }
  const OffPolicyOptions& options() const { return options_; }

 private:
  torch::Tensor ActorInput(const torch::Tensor& obs, const torch::Tensor& base) const;
  torch::Tensor CriticInput(const torch::Tensor& obs, const torch::Tensor& base,
                            const torch::Tensor& action) const;
  // Squashed action and (SAC) its log-likelihood for actor output `out`, noise `eps` (or none).
  std::pair<torch::Tensor, torch::Tensor> Squash(const torch::Tensor& out,
                                                 const torch::Tensor& base,
                                                 const torch::Tensor& eps) const;
  torch::Tensor Normal(int64_t rows, core::Rng& rng) const;
  // The networks and optimizers by the names they are saved under.
  std::vector<std::pair<const char*, torch::nn::Module*>> Modules();
  std::vector<std::pair<const char*, torch::optim::Optimizer*>> Optimizers();

  int obs_dim_, action_dim_;
  OffPolicyOptions options_;
  bool sac_;
  torch::nn::Sequential actor_{nullptr}, actor_target_{nullptr};
  torch::nn::Sequential q1_{nullptr}, q2_{nullptr}, q1_target_{nullptr}, q2_target_{nullptr};
  torch::Tensor log_alpha_;
  torch::Tensor mask_;  // [action_dim]: 1 where the actor acts (residual_dims), else 0
  std::unique_ptr<torch::optim::Adam> actor_opt_, critic_opt_, alpha_opt_;
  int64_t updates_ = 0;
  nlohmann::json info_ = nlohmann::json::object();
};

}  // namespace twinforge::learn
