#include "learn/data_parallel.h"

#include <gtest/gtest.h>

#include "core/error.h"
#include "learn/torch_runtime.h"

namespace twinforge::learn {
namespace {

PolicyConfig SmallCloudPolicy() {
  PolicyConfig c;
  c.points = 32;
  c.proprio_dim = 9;
  c.action_dim = 14;
  c.hidden = 32;
  return c;
}

struct Data {
  torch::Tensor points, proprio, moves;
};

Data RandomBatch(int64_t rows, uint64_t seed) {
  torch::manual_seed(seed);
  return {torch::randn({rows, 32, 4}), torch::randn({rows, 9}), torch::randint(0, 14, {rows})};
}

torch::Tensor Loss(PolicyNet& net, const Data& d, int64_t i, int64_t j) {
  return -net->LogProb(net->forward(d.points.slice(0, i, j), d.proprio.slice(0, i, j)),
                       d.moves.slice(0, i, j))
              .mean();
}

std::vector<torch::Tensor> Grads(PolicyNet& net) {
  std::vector<torch::Tensor> g;
  for (const torch::Tensor& p : net->parameters())
    g.push_back(p.grad().defined() ? p.grad().clone() : torch::zeros_like(p));
  return g;
}

// `steps` Adam steps on fixed batches, the gradient from DataParallel.
std::vector<torch::Tensor> Train(int shards, int threads, int steps) {
  torch::manual_seed(7);
  PolicyNet net(SmallCloudPolicy());
  torch::optim::Adam adam(net->parameters(), torch::optim::AdamOptions(1e-2));
  DataParallel parallel(net, shards, threads);
  for (int s = 0; s < steps; ++s) {
    const Data d = RandomBatch(13, 100 + s);  // odd: the shards differ in size
    parallel.Backward(13, [&](PolicyNet& r, int64_t i, int64_t j) { return Loss(r, d, i, j); });
    adam.step();
  }
  std::vector<torch::Tensor> w;
  for (const torch::Tensor& p : net->parameters()) w.push_back(p.detach().clone());
  return w;
}

TEST(DataParallel, ShardedGradientIsTheWholeBatchGradient) {
  PinMathThreads(1);
  torch::manual_seed(3);
  PolicyNet net(SmallCloudPolicy());
  const Data d = RandomBatch(13, 5);
  const double whole = Loss(net, d, 0, 13).item<double>();
  Loss(net, d, 0, 13).backward();
  const std::vector<torch::Tensor> expected = Grads(net);

  DataParallel parallel(net, 3, 2);
  const double loss =
      parallel.Backward(13, [&](PolicyNet& r, int64_t i, int64_t j) { return Loss(r, d, i, j); });
  EXPECT_NEAR(loss, whole, 1e-5);
  const std::vector<torch::Tensor> got = Grads(net);  // replaced, not added to the first
  ASSERT_EQ(got.size(), expected.size());
  double largest = 0;
  for (std::size_t i = 0; i < got.size(); ++i) {
    EXPECT_TRUE(torch::allclose(got[i], expected[i], 1e-4, 1e-6)) << "parameter " << i;
    largest = std::max(largest, expected[i].abs().max().item<double>());
  }
  EXPECT_GT(largest, 1e-3);  // the check above compared real gradients
}

TEST(DataParallel, SameWeightsWithOneThreadOrTwo) {
  PinMathThreads(1);
  const std::vector<torch::Tensor> one = Train(2, 1, 5), two = Train(2, 2, 5);
  ASSERT_EQ(one.size(), two.size());
  for (std::size_t i = 0; i < one.size(); ++i)
    EXPECT_TRUE(torch::equal(one[i], two[i])) << "parameter " << i;
  // The weights did move, so the equality is not of two untouched networks.
  torch::manual_seed(7);
  PolicyNet start(SmallCloudPolicy());
  EXPECT_FALSE(torch::equal(start->parameters()[0], one[0]));
}

TEST(DataParallel, MoreShardsThanRowsUnderNoGradAndTheGeneratorUntouched) {
  PinMathThreads(1);
  torch::manual_seed(11);
  PolicyNet net(SmallCloudPolicy());
  const Data d = RandomBatch(1, 9);
  Loss(net, d, 0, 1).backward();
  const std::vector<torch::Tensor> expected = Grads(net);

  torch::manual_seed(12);
  const torch::Tensor draw = torch::rand({4});
  torch::manual_seed(12);
  DataParallel parallel(net, 4, 2);  // making replicas draws their initial weights
  EXPECT_TRUE(torch::equal(torch::rand({4}), draw));

  {
    torch::NoGradGuard caller;  // as a benchmark or an evaluation loop may hold one
    parallel.Backward(1, [&](PolicyNet& r, int64_t i, int64_t j) { return Loss(r, d, i, j); });
  }
  const std::vector<torch::Tensor> got = Grads(net);
  for (std::size_t i = 0; i < got.size(); ++i)
    EXPECT_TRUE(torch::allclose(got[i], expected[i], 1e-5, 1e-7)) << "parameter " << i;
  EXPECT_THROW(
      parallel.Backward(0, [&](PolicyNet& r, int64_t i, int64_t j) { return Loss(r, d, i, j); }),
      core::Error);
}

}  // namespace
}  // namespace twinforge::learn
