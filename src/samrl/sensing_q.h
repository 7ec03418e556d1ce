// SAM-RL's sensing-aware Q-function: Q(view, action), the return expected when the actor takes
// `action` having seen the scene from a camera pose, learned by regressing the returns of
// simulated episodes on the views they were taken with. The view is the soft rasterizer's depth,
// silhouette and target mask, so Q is differentiable in the camera pose and AscendView can choose
// the view.
//
// Includes <torch/torch.h>: include it only from .cpp files and tests.
#pragma once

#include <torch/torch.h>

#include <filesystem>
#include <vector>

#include "core/pinhole.h"
#include "core/rng.h"
#include "real2sim/calibrate/soft_render.h"
#include "samrl/active_camera.h"

namespace twinforge::samrl {

// A view as the network reads it: [3, H, W] float, depth (m, 0 = nothing), silhouette and the
// red channel, which TargetVisibility's meshes give the targets (the objects the actor must see)
// and nothing else.
constexpr int kViewChannels = 3;
torch::Tensor ViewInput(const real2sim::SoftImage& image);

// Two strided convolutions over the view, then an MLP with the action: a scalar.
class SensingQNetImpl : public torch::nn::Module {
 public:
  SensingQNetImpl(int height, int width, int action_dim, int hidden = 128);
  // views [B, kViewChannels, H, W], actions [B, action_dim] -> [B]
  torch::Tensor forward(const torch::Tensor& views, const torch::Tensor& actions);
  int action_dim() const { return action_dim_; }

 private:
  int action_dim_;
  torch::nn::Sequential conv_{nullptr}, head_{nullptr};
};
TORCH_MODULE(SensingQNet);

// One look of a simulated episode: the view its actor saw, its action (or plan) and the
// episode's return. The looks of one episode share a `group`, so that a fit holds out whole
// episodes (-1: the sample is its own).
struct ViewReturn {
  torch::Tensor view;    // [kViewChannels, H, W]
  torch::Tensor action;  // [action_dim]
  double ret = 0;
  int group = -1;
};

// The twin actor's plan as Q's action: the expert step it does next (of `steps`), one-hot. A step
// past the last (the script done) reads as the last.
torch::Tensor PlanInput(int step, int steps);

struct SensingQOptions {
  int steps = 400;
  int batch = 32;
  double learning_rate = 1e-3;
  double validation = 0.2;  // share of the samples' groups (episodes) held out
  uint64_t seed = 1;
};

struct SensingQReport {
  double train_loss = 0, valid_loss = 0;  // mean squared error at the end
  double valid_baseline = 0;  // predicting the mean training return on the held-out samples
};

// Fits `net` to the samples by mean squared error (Adam, minibatches drawn from options.seed;
// the net's initial weights are the caller's: seed LibTorch before constructing it).
SensingQReport FitSensingQ(SensingQNet& net, const std::vector<ViewReturn>& samples,
                           const SensingQOptions& options = {});

// Q of the view rendered from a pose, for one action: the score AscendView climbs.
ViewScore QScore(SensingQNet& net, const torch::Tensor& action);
// At each look, Q of the views for the actor's plan then (PlanInput of its next step), or of the
// view alone for a Q without an action.
LookScore QLookScore(SensingQNet& net);

}  // namespace twinforge::samrl
