#include "learn/bench.h"

#include <algorithm>
#include <functional>

#include "core/measure.h"
#include "core/rng.h"
#include "learn/data_parallel.h"
#include "learn/policy_net.h"
#include "learn/ppo_update.h"
#include "learn/torch_runtime.h"

namespace twinforge::learn {

namespace {

// Median seconds of `repeats` calls of `work` (after one warm-up call).
double MedianSeconds(int repeats, const std::function<void()>& work) {
  work();
  std::vector<double> t;
  for (int r = 0; r < repeats; ++r) {
    const auto start = core::Clock::now();
    work();
    t.push_back(core::SecondsSince(start));
  }
  return core::Median(t);
}

// Multiply-adds of one sample through Linear layers of these widths, times two (FLOPs).
double MlpFlops(const std::vector<int>& widths) {
  double f = 0;
  for (std::size_t k = 1; k < widths.size(); ++k) f += 2.0 * widths[k - 1] * widths[k];
  return f;
}

}  // namespace

double MatmulPeakGflops(int repeats) {
  torch::NoGradGuard no_grad;
  const int n = 1024;
  const torch::Tensor a = torch::randn({n, n}), b = torch::randn({n, n});
  torch::Tensor c = torch::empty({n, n});
  const double mm = MedianSeconds(repeats, [&] {
    for (int k = 0; k < 4; ++k) torch::mm_out(c, a, b);
  });
  return 4 * 2.0 * n * n * double(n) / mm / 1e9;
}

double PpoSampleFlops(int state_dim, int hidden, int action_dim) {
  return 3 * (MlpFlops({state_dim, hidden, hidden, action_dim}) +
              MlpFlops({state_dim, hidden, hidden, 1}));
}

nlohmann::json RunLearnBench(const LearnBenchOptions& options) {
  torch::NoGradGuard outer_no_grad;
  nlohmann::json out;
  const BlasInfo blas = QueryBlas();
  out["blas"] = {{"vendor", blas.vendor}, {"library", blas.library}, {"threads", blas.threads}};
  out["torch_threads"] = TorchThreads();
  out["repeats"] = options.repeats;

  const double peak = MatmulPeakGflops(options.repeats);
  out["matmul_peak_gflops"] = peak;

  // PPO + BC minibatch step (TrainPpo's own code) on the teacher shape.
  {
    torch::manual_seed(1);
    PpoOptions ppo;
    PolicyConfig config;
    config.point_features = 0;
    config.proprio_dim = options.state_dim;
    PpoModel model(config, ppo);
    const int64_t B = options.minibatch;
    const torch::Tensor obs = torch::randn({B, options.state_dim});
    const torch::Tensor actions = torch::randint(0, config.action_dim, {B}, torch::kLong);
    const torch::Tensor old_logp = torch::full({B}, -std::log(14.0));
    const torch::Tensor adv = torch::randn({B}), returns = torch::rand({B});
    DemoSteps demos{torch::randn({500, options.state_dim}),
                    torch::randint(0, config.action_dim, {500}, torch::kLong)};
    core::Rng rng(1);
    const double step = MedianSeconds(options.repeats, [&] {
      torch::AutoGradMode grad(true);
      PpoMinibatch(model, ppo, obs, actions, old_logp, adv, returns, &demos, rng);
    });
    const double flops = PpoSampleFlops(options.state_dim, ppo.hidden, config.action_dim);
    const double samples = double(B) / step;
    out["ppo_update"] = {{"minibatch", B},
                         {"state_dim", options.state_dim},
                         {"samples_per_s", samples},
                         {"gflops", samples * flops / 1e9},
                         {"share_of_matmul_peak", samples * flops / 1e9 / peak}};
  }

  // Point-cloud BC step: DP3-style encoder, batch 64, Adam.
  {
    torch::manual_seed(2);
    PolicyConfig config;
    config.points = options.cloud_points;
    PolicyNet net(config);
    torch::optim::Adam optimizer(net->parameters(), torch::optim::AdamOptions(1e-3));
    const int64_t B = options.cloud_batch;
    const torch::Tensor points = torch::randn({B, config.points, 4});
    const torch::Tensor proprio = torch::randn({B, config.proprio_dim});
    const torch::Tensor actions = torch::randint(0, config.action_dim, {B}, torch::kLong);
    const double step = MedianSeconds(options.repeats, [&] {
      torch::AutoGradMode grad(true);
      const torch::Tensor loss = -net->LogProb(net->forward(points, proprio), actions).mean();
      optimizer.zero_grad();
      loss.backward();
      optimizer.step();
    });
    // The same step as BC and distillation take it: the batch in kGradientShards shards, each on
    // its own copy of the network, on one thread and on two.
    const auto sharded = [&](int threads) {
      DataParallel parallel(net, kGradientShards, threads);
      return MedianSeconds(options.repeats, [&] {
        parallel.Backward(B, [&](PolicyNet& r, int64_t i, int64_t j) {
          return -r->LogProb(r->forward(points.slice(0, i, j), proprio.slice(0, i, j)),
                             actions.slice(0, i, j))
                      .mean();
        });
        optimizer.step();
      });
    };
    const double one = sharded(1), two = sharded(2);
    const double flops = 3 * config.points * MlpFlops({4, 64, 128, 256});
    const double clouds = double(B) / step;
    out["bc_point_cloud"] = {{"batch", B},
                             {"points", config.points},
                             {"clouds_per_s", clouds},
                             {"gflops", clouds * flops / 1e9},
                             {"share_of_matmul_peak", clouds * flops / 1e9 / peak},
                             {"shards", kGradientShards},
                             {"sharded_1_thread_clouds_per_s", double(B) / one},
                             {"sharded_2_threads_clouds_per_s", double(B) / two},
                             {"sharded_2_threads_speedup_vs_whole_batch", step / two}};
  }
  return out;
}

}  // namespace twinforge::learn
