// Losses that compare a soft rendering (soft_render.h) or a point cloud with what a real camera
// saw. All take and return double tensors and are differentiable in their first argument(s).
//
// Includes <torch/torch.h>: include it only from the calibrate module's .cpp files and tests.
#pragma once

#include <torch/torch.h>

namespace twinforge::real2sim {

// Mean absolute colour difference over `mask` ([H, W] 0/1: the segmented region), each pixel
// weighted by the rendered silhouette. rgb and target are [H, W, 3] in [0, 1].
torch::Tensor RgbLoss(const torch::Tensor& rgb, const torch::Tensor& silhouette,
                      const torch::Tensor& target, const torch::Tensor& mask);

// Mean Huber depth error (m, Huber width `delta`) over the pixels where the target has a return.
// A pixel the rendering does not cover (silhouette <= 0.5) or misses by more than `outlier` (a
// person, a cable: something the twin does not have) costs what `outlier` would, without a
// gradient: a pose cannot lower the loss by pushing what disagrees out of view. `weight` ([H, W],
// optional) scales each pixel's term.
torch::Tensor DepthLoss(const torch::Tensor& depth, const torch::Tensor& silhouette,
                        const torch::Tensor& target, double delta = 0.01, double outlier = 0.05,
                        const torch::Tensor& weight = {});

// 1 - soft intersection over union of a rendered silhouette and a target mask ([H, W] in [0, 1]).
torch::Tensor SilhouetteLoss(const torch::Tensor& silhouette, const torch::Tensor& target);

// Symmetric Chamfer distance: the mean distance from each point of `a` [N, 3] to its nearest in
// `b` [M, 3], plus the same from b to a.
torch::Tensor ChamferDistance(const torch::Tensor& a, const torch::Tensor& b);

// Earth Mover's Distance between two clouds with equal weights per point (1/N and 1/M), with
// entropic regularization `epsilon` (m) solved by log-domain Sinkhorn iterations: the transport
// plan's cost sum P_ij |a_i - b_j|. The plan is found without gradients; the gradient is that of
// the cost at the plan (the envelope theorem), which is exact at convergence.
torch::Tensor SinkhornEmd(const torch::Tensor& a, const torch::Tensor& b, double epsilon = 0.002,
                          int iterations = 200);

}  // namespace twinforge::real2sim
