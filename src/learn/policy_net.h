// Policy networks on LibTorch: a DP3-style point-cloud encoder (a shared per-point MLP with layer
// norm, max-pooled; ~60k parameters) or none (privileged state), concatenated with
// proprioception, then an MLP with a discrete (14 moves) or Gaussian (continuous) head.
//
// Includes <torch/torch.h>: include it only from learn's .cpp files and tests.
#pragma once

#include <torch/torch.h>

#include <filesystem>
#include <string>
#include <vector>

#include "core/config.h"

namespace twinforge::learn {

struct PolicyConfig {
  int point_features = 4;  // per point: x, y, z, and 1 for the arm's points (0: no points)
  int points = 512;        // points per observation
  int proprio_dim = 9;     // or the privileged state's size
  int action_dim = 14;     // discrete: number of moves; continuous: action size
  bool discrete = true;
  int hidden = 256;  // head MLP width (two layers)
  // Continuous: each component's typical size (a task's per-step limits: m, rad, 1 for the
  // gripper). The head learns actions divided by it, so a 3 cm move and the gripper's +-1 are
  // fitted to the same relative precision, and log_std starts at half of it. Empty: all 1.
  std::vector<double> action_scale;
  template <class A>
  void Serialize(A& a) {
    a("point_features", point_features);
    a("points", points);
    a("proprio_dim", proprio_dim);
    a("action_dim", action_dim);
    a("discrete", discrete);
    a("hidden", hidden);
    a("action_scale", action_scale);
    a.Require(action_scale.empty() || (!discrete && int(action_scale.size()) == action_dim),
              "action_scale", "one positive size per continuous action component, or none");
    for (double x : action_scale) a.Require(x > 0, "action_scale", "positive sizes");
    a.Require(point_features >= 0 && points > 0 && proprio_dim >= 0 && action_dim > 0, "points",
              "non-negative input sizes and a positive action size");
  }
};

// points [B, N, F] -> [B, 64]: per point Linear-LayerNorm-ReLU 64, 128, then Linear-LayerNorm
// 256, max over the points, Linear-LayerNorm 64.
class PointEncoderImpl : public torch::nn::Module {
 public:
  explicit PointEncoderImpl(int features);
  torch::Tensor forward(const torch::Tensor& points);
  static constexpr int kOut = 64;

 private:
  torch::nn::Sequential per_point_{nullptr}, project_{nullptr};
};
TORCH_MODULE(PointEncoder);

class PolicyNetImpl : public torch::nn::Module {
 public:
  explicit PolicyNetImpl(const PolicyConfig& config);
  // Discrete: logits [B, action_dim]. Continuous: the Gaussian's mean [B, action_dim] (its log
  // standard deviation is `log_std`). `points` may be undefined when point_features is 0.
  // `proprio` is normalized first (see Normalize).
  torch::Tensor forward(const torch::Tensor& points, const torch::Tensor& proprio);
  // (proprio - obs_mean) / obs_std, clipped to +-10: the observation normalization PPO learns
  // for the privileged state. The buffers are saved with the weights; they stay 0 and 1 (no
  // change) for a policy trained by BC.
  torch::Tensor Normalize(const torch::Tensor& proprio) const;
  // What the head reads: the encoder's features (when the policy sees points) and the normalized
  // proprioception, [B, HeadInputDim()]. A residual policy reads it too.
  torch::Tensor HeadInput(const torch::Tensor& points, const torch::Tensor& proprio);
  int HeadInputDim() const;
  // The head's output for a HeadInput: forward() without running the encoder again.
  torch::Tensor Head(const torch::Tensor& head_input);
  // The head's output for an already normalized input.
  torch::Tensor ForwardNormalized(const torch::Tensor& points, const torch::Tensor& normalized);
  // Log-likelihood of `actions` (discrete: [B] indices; continuous: [B, action_dim]), per row.
  torch::Tensor LogProb(const torch::Tensor& output, const torch::Tensor& actions) const;
  const PolicyConfig& config() const { return config_; }
  const torch::Tensor& ActionScale() const { return action_scale_; }
  torch::Tensor log_std;            // [action_dim], continuous only
  torch::Tensor obs_mean, obs_std;  // [proprio_dim] buffers
  static constexpr double kObsClip = 10.0;

 private:
  torch::Tensor Features(const torch::Tensor& points, const torch::Tensor& normalized);
  PolicyConfig config_;
  torch::Tensor action_scale_;  // [action_dim] (continuous), from the config: not a weight
  PointEncoder encoder_{nullptr};
  torch::nn::Sequential head_{nullptr};
};
TORCH_MODULE(PolicyNet);

// One file with the weights and the config (a LibTorch archive), written to a temporary name
// and renamed.
void SavePolicy(PolicyNet& net, const std::filesystem::path& path);
// Throws IoError when missing, Error naming the file when it is not a twinforge policy.
PolicyNet LoadPolicy(const std::filesystem::path& path);

// Writes the policy as a TorchScript module that Python loads with `torch.jit.load(path)`:
// `forward(points [B, N, F], proprio [B, P]) -> logits or mean`, normalization included; for a
// continuous policy `log_std` is an attribute. Point-free policies ignore `points`.
void ExportTorchScript(PolicyNet& net, const std::filesystem::path& path);

int64_t ParameterCount(torch::nn::Module& module);

}  // namespace twinforge::learn
