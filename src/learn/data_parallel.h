// Data-parallel gradients for a policy on the CPU: one batch, cut into a fixed number of shards,
// each shard's loss differentiated by its own copy of the network on its own thread, the
// gradients summed in shard order.
//
// Every process pins BLAS and LibTorch to one thread (learn/torch_runtime.h), so a point-cloud
// network's backward pass ran on one core while the other idled: distillation spent about 17 of
// its 24 minutes there. The shard count is fixed (kGradientShards), not the thread count, so the
// same seed gives the same weights with 1 thread or 2: each shard's arithmetic is the same
// wherever it runs, and the sum is taken in one order.
#pragma once

#include <cstdint>
#include <functional>
#include <vector>

#include "core/thread_pool.h"
#include "learn/policy_net.h"

namespace twinforge::learn {

// Shards per batch of BC and distillation (the machines have two cores).
inline constexpr int kGradientShards = 2;

class DataParallel {
 public:
  // Gradients for `net` over `shards` slices of each batch, on up to `threads` threads.
  DataParallel(PolicyNet net, int shards, int threads);

  // The mean loss of rows [begin, end) of the batch, computed by `replica` (which holds `net`'s
  // weights and mode). It must use only `replica` and the rows it is given.
  using ShardLoss = std::function<torch::Tensor(PolicyNet& replica, int64_t begin, int64_t end)>;

  // Leaves in `net`'s gradients those of the mean loss over all `rows` of the batch (each shard's
  // weighted by its share of the rows), replacing what they held, and returns that mean loss.
  double Backward(int64_t rows, const ShardLoss& loss);

 private:
  PolicyNet net_;
  std::vector<PolicyNet> replicas_;  // shards 1..n-1; shard 0 is `net_` itself
  core::ThreadPool pool_;
};

}  // namespace twinforge::learn
