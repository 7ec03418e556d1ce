// What PPO trains and one minibatch step of PPO + BC: TrainPpo's update and the learning
// benchmark (`train bench`) run this same code.
//
// Includes <torch/torch.h> (via policy_net.h): include it only from learn's .cpp files and tests.
#pragma once

#include <memory>
#include <vector>

#include "core/rng.h"
#include "learn/policy_net.h"
#include "learn/ppo.h"

namespace twinforge::learn {

struct PpoModel {
  PpoModel(const PolicyConfig& config, const PpoOptions& options);
  PolicyNet policy;
  torch::nn::Sequential value;        // normalized state -> [hidden, hidden] tanh -> 1
  std::vector<torch::Tensor> params;  // the policy's, then the value's
  std::unique_ptr<torch::optim::Adam> optimizer;
};

// Demo steps for the BC loss: raw states [D, S] and actions ([D] long or [D, A]).
struct DemoSteps {
  torch::Tensor states, actions;
};

struct MinibatchStats {
  double policy_loss = 0, value_loss = 0, entropy = 0, approx_kl = 0, bc_loss = 0;
};

// One optimizer step on a minibatch: normalized states, actions taken, their log-likelihoods at
// rollout time, GAE advantages (normalized here) and returns; plus, with `demos`, a BC batch of
// options.bc_batch steps drawn with `demo_rng`. `value_only`: the value loss alone (the critic's
// warm-up); the policy is left as it is.
MinibatchStats PpoMinibatch(PpoModel& model, const PpoOptions& options, const torch::Tensor& obs,
                            const torch::Tensor& actions, const torch::Tensor& old_logp,
                            const torch::Tensor& advantages, const torch::Tensor& returns,
                            const DemoSteps* demos, core::Rng& demo_rng, bool value_only = false);

}  // namespace twinforge::learn
