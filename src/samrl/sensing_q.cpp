#include "samrl/sensing_q.h"

#include <algorithm>
#include <map>

#include "core/error.h"

namespace twinforge::samrl {

torch::Tensor ViewInput(const real2sim::SoftImage& image) {
  return torch::stack({image.depth, image.silhouette, image.rgb.select(2, 0)}).to(torch::kFloat32);
}

SensingQNetImpl::SensingQNetImpl(int height, int width, int action_dim, int hidden)
    : action_dim_(action_dim) {
  if (height < 8 || width < 8 || action_dim < 0)
    throw core::Error("sensing Q: views of at least 8 x 8 pixels and a non-negative action size");
  conv_ = register_module(
      "conv",
      torch::nn::Sequential(
          torch::nn::Conv2d(torch::nn::Conv2dOptions(kViewChannels, 16, 5).stride(2).padding(2)),
          torch::nn::ReLU(),
          torch::nn::Conv2d(torch::nn::Conv2dOptions(16, 32, 3).stride(2).padding(1)),
          torch::nn::ReLU(),
          torch::nn::AdaptiveAvgPool2d(torch::nn::AdaptiveAvgPool2dOptions({4, 4})),
          torch::nn::Flatten()));
  head_ = register_module(
      "head", torch::nn::Sequential(torch::nn::Linear(32 * 16 + action_dim, hidden),
                                    torch::nn::ReLU(), torch::nn::Linear(hidden, hidden),
                                    torch::nn::ReLU(), torch::nn::Linear(hidden, 1)));
}

torch::Tensor SensingQNetImpl::forward(const torch::Tensor& views, const torch::Tensor& actions) {
  torch::Tensor x = conv_->forward(views);
  if (action_dim_ > 0) x = torch::cat({x, actions}, 1);
  return head_->forward(x).view({-1});
}

torch::Tensor PlanInput(int step, int steps) {
  if (steps < 1 || step < 0)
    throw core::Error("sensing Q: a plan is a step of at least one, got step " +
                      std::to_string(step) + " of " + std::to_string(steps));
  torch::Tensor plan = torch::zeros({steps});
  plan[std::min(step, steps - 1)] = 1.0f;
  return plan;
}

SensingQReport FitSensingQ(SensingQNet& net, const std::vector<ViewReturn>& samples,
                           const SensingQOptions& options) {
  const int n = int(samples.size());
  core::Rng rng(options.seed, 0x9e5);
  // The groups in a shuffled order, each group's samples together: the first groups are held out.
  // A sample of no group is its own, after the groups (ungrouped samples keep their order).
  std::map<std::pair<int, int>, std::vector<int>> groups;
  for (int i = 0; i < n; ++i)
    groups[samples[i].group >= 0 ? std::pair(0, samples[i].group) : std::pair(1, i)].push_back(i);
  std::vector<const std::vector<int>*> shuffled;
  for (const auto& [group, members] : groups) shuffled.push_back(&members);
  rng.Shuffle(shuffled);
  std::vector<int> order;
  int valid_n = 0;
  const int valid_groups = int(options.validation * double(shuffled.size()));
  for (std::size_t g = 0; g < shuffled.size(); ++g) {
    order.insert(order.end(), shuffled[g]->begin(), shuffled[g]->end());
    if (int(g) < valid_groups) valid_n += int(shuffled[g]->size());
  }
  if (n - valid_n < 2)
    throw core::Error("sensing Q: too few samples to fit (" + std::to_string(n) + ")");
  const auto stack = [&](int first, int last) {
    std::vector<torch::Tensor> v, a;
    std::vector<float> r;
    for (int i = first; i < last; ++i) {
      const ViewReturn& s = samples[order[i]];
      v.push_back(s.view.to(torch::kFloat32));
      a.push_back(s.action.defined() ? s.action.to(torch::kFloat32).view({-1}) : torch::zeros({0}));
      r.push_back(float(s.ret));
    }
    return std::make_tuple(torch::stack(v), torch::stack(a), torch::tensor(r));
  };
  const auto [train_v, train_a, train_r] = stack(valid_n, n);
  const auto [valid_v, valid_a, valid_r] =
      valid_n > 0 ? stack(0, valid_n)
                  : std::make_tuple(torch::Tensor(), torch::Tensor(), torch::Tensor());
  torch::optim::Adam adam(net->parameters(), torch::optim::AdamOptions(options.learning_rate));
  const int train_n = n - valid_n;
  for (int step = 0; step < options.steps; ++step) {
    std::vector<int64_t> rows(std::min(options.batch, train_n));
    for (auto& r : rows) r = int64_t(rng.Index(uint64_t(train_n)));
    const torch::Tensor idx = torch::tensor(rows);
    const torch::Tensor loss =
        torch::mse_loss(net->forward(train_v.index_select(0, idx), train_a.index_select(0, idx)),
                        train_r.index_select(0, idx));
    adam.zero_grad();
    loss.backward();
    adam.step();
  }
  torch::NoGradGuard no_grad;
  SensingQReport report;
  report.train_loss = torch::mse_loss(net->forward(train_v, train_a), train_r).item<double>();
  if (valid_n > 0) {
    report.valid_loss = torch::mse_loss(net->forward(valid_v, valid_a), valid_r).item<double>();
    report.valid_baseline = (valid_r - train_r.mean()).pow(2).mean().item<double>();
  }
  return report;
}

ViewScore QScore(SensingQNet& net, const torch::Tensor& action) {
  const torch::Tensor a =
      action.defined() ? action.to(torch::kFloat32).view({1, -1}) : torch::zeros({1, 0});
  return [net, a](const real2sim::SoftImage& image) mutable {
    return net->forward(ViewInput(image).unsqueeze(0), a).sum();
  };
}

LookScore QLookScore(SensingQNet& net) {
  return [net](const LookContext& context) mutable {
    return QScore(net,
                  net->action_dim() > 0 ? PlanInput(context.step, context.steps) : torch::Tensor());
  };
}

}  // namespace twinforge::samrl
