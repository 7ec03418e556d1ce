#include "learn/evaluate.h"

#include <chrono>

#include "core/error.h"
#include "core/rng.h"
#include "core/thread_pool.h"
#include "learn/bc.h"
#include "learn/policy_net.h"
#include "sim/camera.h"
#include "sim/env.h"

namespace twinforge::learn {

PolicyEvalReport EvaluatePolicy(const std::filesystem::path& policy,
                                std::shared_ptr<const sim::Task> task,
                                const PolicyEvalOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  PolicyNet net = LoadPolicy(policy);
  net->eval();
  const PolicyConfig& config = net->config();
  const bool discrete = task->spec().control.action == sim::ActionMode::kDiscrete;
  const int action_dim = discrete ? sim::kDiscreteActions : sim::kContinuousActionDim;
  if (config.discrete != discrete || config.action_dim != action_dim ||
      config.proprio_dim != sim::kProprioDim || config.point_features != 4)
    throw core::Error(policy.string() + ": a policy for " + std::to_string(config.action_dim) +
                      (config.discrete ? " discrete" : "") + " actions from " +
                      std::to_string(config.proprio_dim) + "-d proprioception and points; task '" +
                      task->spec().name + "' needs " + std::to_string(action_dim) +
                      (discrete ? " discrete" : "") + " actions from " +
                      std::to_string(sim::kProprioDim) + "-d proprioception");
  PolicyEvalReport report;
  report.episodes = options.episodes;
  report.steps.assign(options.episodes, -1);
  core::ThreadPool pool(options.threads);
  const int blocks = pool.size();
  pool.ParallelFor(blocks, [&](int64_t block) {
    torch::NoGradGuard no_grad;
    sim::Env env(task, static_cast<int>(block));
    sim::CloudMaker::Options cloud_options;
    cloud_options.scene_points = options.scene_points;
    cloud_options.arm_points = options.arm_points;
    sim::CloudMaker clouds(*task, env.model(), cloud_options);
    std::vector<float> scene(3 * options.scene_points), arm(3 * options.arm_points);
    PointSampling sampling;
    sampling.n = config.points;
    torch::Tensor points = torch::empty({1, config.points, 4});
    torch::Tensor proprio = torch::empty({1, sim::kProprioDim});
    for (int64_t i = options.episodes * block / blocks; i < options.episodes * (block + 1) / blocks;
         ++i) {
      const uint64_t seed = core::MixSeed(options.seed, static_cast<uint64_t>(i));
      env.Reset(seed, options.level);
      core::Rng cloud_rng(seed, 0xc1);
      core::Rng sample_rng(seed, 0x5a);
      for (int t = 0; t < task->spec().horizon; ++t) {
        clouds.Make(env.model(), env.data(), env.base(), cloud_rng, scene.data(), arm.data());
        SamplePoints(scene.data(), options.scene_points, arm.data(), options.arm_points, sampling,
                     false, sample_rng, points.data_ptr<float>());
        env.Proprio(proprio.data_ptr<float>());
        const torch::Tensor out = net->forward(points, proprio);
        sim::Action action;
        if (discrete) {
          action = sim::Action::Discrete(static_cast<int>(out.argmax(1).item<int64_t>()));
        } else {
          std::array<double, sim::kContinuousActionDim> v{};
          for (int k = 0; k < sim::kContinuousActionDim; ++k) v[k] = out[0][k].item<double>();
          action = sim::Action::Continuous(v);
        }
        const sim::StepResult r = env.Step(action);
        if (r.success) {
          report.steps[i] = t + 1;
          break;
        }
        if (r.done) break;
      }
    }
  });
  for (int s : report.steps) report.successes += s > 0;
  report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return report;
}

}  // namespace twinforge::learn
