#include "real2sim/calibrate/losses.h"

#include <cmath>

namespace twinforge::real2sim {

torch::Tensor RgbLoss(const torch::Tensor& rgb, const torch::Tensor& silhouette,
                      const torch::Tensor& target, const torch::Tensor& mask) {
  const auto weight = silhouette * mask;
  const auto error = (rgb - target).abs().sum(-1);
  return (weight * error).sum() / (3 * mask.sum() + 1e-9);
}

torch::Tensor DepthLoss(const torch::Tensor& depth, const torch::Tensor& silhouette,
                        const torch::Tensor& target, double delta, double outlier,
                        const torch::Tensor& weight) {
  const auto returns = target > 0;
  const auto inlier =
      (returns & (silhouette.detach() > 0.5) & ((depth - target).detach().abs() < outlier))
          .to(torch::kFloat64);
  const auto huber = torch::huber_loss(depth * inlier, target * inlier, at::Reduction::None, delta);
  // What an outlier costs: the Huber loss at the outlier distance.
  const double cap = delta * (outlier - 0.5 * delta);
  const auto outliers = returns.to(torch::kFloat64) - inlier;
  const auto per_pixel = huber + cap * outliers;
  return (weight.defined() ? per_pixel * weight : per_pixel).sum() / (returns.sum() + 1e-9);
}

torch::Tensor SilhouetteLoss(const torch::Tensor& silhouette, const torch::Tensor& target) {
  const auto intersection = (silhouette * target).sum();
  const auto uni = (silhouette + target - silhouette * target).sum();
  return 1 - intersection / (uni + 1e-9);
}

torch::Tensor ChamferDistance(const torch::Tensor& a, const torch::Tensor& b) {
  const auto d = torch::cdist(a, b);
  return std::get<0>(d.min(1)).mean() + std::get<0>(d.min(0)).mean();
}

torch::Tensor SinkhornEmd(const torch::Tensor& a, const torch::Tensor& b, double epsilon,
                          int iterations) {
  const auto cost = torch::cdist(a, b);  // [N, M]
  const int64_t n = a.size(0), m = b.size(0);
  torch::Tensor plan;
  {
    torch::NoGradGuard no_grad;
    const auto c = cost.detach();
    const auto log_a = torch::full({n}, -std::log(static_cast<double>(n)), c.options());
    const auto log_b = torch::full({m}, -std::log(static_cast<double>(m)), c.options());
    auto f = torch::zeros({n}, c.options()), g = torch::zeros({m}, c.options());
    for (int i = 0; i < iterations; ++i) {
      f = epsilon * (log_a - torch::logsumexp((g.unsqueeze(0) - c) / epsilon, 1));
      g = epsilon * (log_b - torch::logsumexp((f.unsqueeze(1) - c) / epsilon, 0));
    }
    plan = torch::exp((f.unsqueeze(1) + g.unsqueeze(0) - c) / epsilon);
  }
  return (plan * cost).sum();
}

}  // namespace twinforge::real2sim
