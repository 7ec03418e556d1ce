#include "learn/data_parallel.h"

#include <ATen/CPUGeneratorImpl.h>

#include <mutex>

#include "core/error.h"

namespace twinforge::learn {

DataParallel::DataParallel(PolicyNet net, int shards, int threads)
    : net_(std::move(net)), pool_(std::max(1, std::min(threads, shards))) {
  if (shards < 1) throw core::Error("DataParallel: needs at least one shard");
  // A new network draws its initial weights from LibTorch's generator; put the generator back so
  // that making the replicas changes no later draw.
  auto generator = at::detail::getDefaultCPUGenerator();
  torch::Tensor state;
  {
    std::lock_guard<std::mutex> lock(generator.mutex());
    state = generator.get_state();
  }
  for (int k = 1; k < shards; ++k) replicas_.emplace_back(net_->config());
  std::lock_guard<std::mutex> lock(generator.mutex());
  generator.set_state(state);
}

double DataParallel::Backward(int64_t rows, const ShardLoss& loss) {
  if (rows <= 0) throw core::Error("DataParallel: an empty batch");
  const int shards = static_cast<int>(replicas_.size()) + 1;
  const auto params = net_->parameters();
  {
    torch::NoGradGuard no_grad;
    const auto buffers = net_->buffers();
    for (PolicyNet& r : replicas_) {
      r->train(net_->is_training());
      const auto rp = r->parameters(), rb = r->buffers();
      for (std::size_t i = 0; i < params.size(); ++i) rp[i].copy_(params[i]);
      for (std::size_t i = 0; i < buffers.size(); ++i) rb[i].copy_(buffers[i]);
    }
  }
  std::vector<double> losses(shards, 0);
  std::vector<std::vector<torch::Tensor>> grads(shards);
  pool_.ParallelFor(shards, [&](int64_t k) {
    torch::AutoGradMode grad(true);  // grad mode is per thread; a caller's NoGradGuard is not ours
    PolicyNet& net = k == 0 ? net_ : replicas_[k - 1];
    std::vector<torch::Tensor> ps = net->parameters();
    for (torch::Tensor& p : ps) p.mutable_grad() = torch::Tensor();
    const int64_t begin = rows * k / shards, end = rows * (k + 1) / shards;
    if (begin == end) return;
    const torch::Tensor l = loss(net, begin, end);
    l.backward();
    losses[k] = l.item<double>();
    for (torch::Tensor& p : ps) grads[k].push_back(p.grad());
  });
  // Sum in shard order, each shard weighted by its rows.
  double total = 0;
  torch::NoGradGuard no_grad;
  for (std::size_t i = 0; i < params.size(); ++i) {
    torch::Tensor sum;
    for (int k = 0; k < shards; ++k) {
      const int64_t n = rows * (k + 1) / shards - rows * k / shards;
      if (n == 0 || !grads[k][i].defined()) continue;
      const double w = double(n) / double(rows);
      if (!sum.defined())
        sum = grads[k][i] * w;
      else
        sum.add_(grads[k][i], w);
    }
    torch::Tensor p = params[i];
    p.mutable_grad() = sum;
  }
  for (int k = 0; k < shards; ++k)
    total += losses[k] * double(rows * (k + 1) / shards - rows * k / shards) / double(rows);
  return total;
}

}  // namespace twinforge::learn
