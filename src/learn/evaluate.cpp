#include "learn/evaluate.h"

#include <optional>

#include "core/error.h"
#include "core/log.h"
#include "core/measure.h"
#include "core/rng.h"
#include "core/thread_pool.h"
#include "learn/bc.h"
#include "learn/rollout.h"
#include "sim/camera.h"
#include "sim/env.h"
#include "sim/expert.h"

namespace twinforge::learn {

namespace {

bool Discrete(const sim::Task& task) {
  return task.spec().control.action == sim::ActionMode::kDiscrete;
}

// One episode's rows as they are taken (the layout `demos record` writes), trimmed to the steps
// taken at the end. Clouds only when `scene_points` > 0.
class EpisodeRecorder {
 public:
  EpisodeRecorder(core::Episode& rec, int horizon, int action_dim, int state_dim, int scene_points,
                  int arm_points, nlohmann::json meta)
      : rec_(rec) {
    const auto rows = std::size_t(horizon);
    rec.actions = core::FloatArray({rows, std::size_t(action_dim)});
    rec.states = core::FloatArray({rows, std::size_t(state_dim)});
    rec.obs["proprio"] = core::FloatArray({rows, std::size_t(sim::kProprioDim)});
    if (scene_points > 0) {
      rec.obs["scene_points"] = core::FloatArray({rows, std::size_t(3 * scene_points)});
      rec.obs["arm_points"] = core::FloatArray({rows, std::size_t(3 * arm_points)});
    }
    rec.meta = std::move(meta);
  }
  // Row `t`: what was seen, and the action taken on it.
  void Row(int t, const sim::Action& action, const std::vector<float>& state,
           const std::vector<float>& proprio, const std::vector<float>* scene = nullptr,
           const std::vector<float>* arm = nullptr) {
    float* a = rec_.actions.row(t);
    if (rec_.actions.row_size() == 1)
      a[0] = float(action.index);
    else
      for (std::size_t k = 0; k < rec_.actions.row_size(); ++k) a[k] = float(action.value[k]);
    std::copy(state.begin(), state.end(), rec_.states.row(t));
    std::copy(proprio.begin(), proprio.end(), rec_.obs["proprio"].row(t));
    if (scene) std::copy(scene->begin(), scene->end(), rec_.obs["scene_points"].row(t));
    if (arm) std::copy(arm->begin(), arm->end(), rec_.obs["arm_points"].row(t));
  }
  void Outcome(const sim::StepResult& r) {
    rec_.rewards.push_back(r.reward);
    rec_.dones.push_back(r.success || r.done);
  }
  void Finish() {
    const std::size_t taken = rec_.rewards.size();
    const auto trim = [taken](core::FloatArray& a) {
      a.data.resize(taken * a.row_size());
      a.shape[0] = taken;
    };
    trim(rec_.actions);
    trim(rec_.states);
    for (auto& [key, value] : rec_.obs) trim(value);
  }

 private:
  core::Episode& rec_;
};

}  // namespace

sim::Action ChooseAction(const PolicyNet& net, const torch::Tensor& out,
                         const PolicyEvalOptions& options, core::Rng& rng) {
  const PolicyConfig& config = net->config();
  if (config.discrete) {
    if (!options.sample)
      return sim::Action::Discrete(static_cast<int>(out.argmax(1).item<int64_t>()));
    const torch::Tensor p = torch::softmax(out[0] / options.temperature, 0);
    return sim::Action::Discrete(SampleIndex(p.data_ptr<float>(), config.action_dim, rng));
  }
  return SampleGaussian(out.data_ptr<float>(), net->log_std.data_ptr<float>(),
                        options.sample ? options.temperature : 0.0, rng);
}

int SampleIndex(const float* probabilities, int n, core::Rng& rng) {
  double u = rng.Uniform();
  for (int k = 0; k < n; ++k)
    if ((u -= probabilities[k]) < 0) return k;
  return n - 1;
}

sim::Action SampleGaussian(const float* mean, const float* log_std, double scale, core::Rng& rng) {
  std::array<double, sim::kContinuousActionDim> v{};
  for (int k = 0; k < sim::kContinuousActionDim; ++k)
    v[k] = mean[k] + (scale > 0 ? std::exp(log_std[k]) * scale * rng.Normal() : 0.0);
  return sim::Action::Continuous(v);
}

std::vector<double> ContinuousActionScale(const sim::ActionLimits& limits) {
  const double t = limits.translation, r = limits.rotation;
  return {t, t, t, r, r, r, 1.0};
}

void CheckPolicyFitsTask(const PolicyConfig& config, const sim::Task& task,
                         const std::string& what) {
  const bool discrete = Discrete(task);
  const int action_dim = discrete ? sim::kDiscreteActions : sim::kContinuousActionDim;
  const bool points = config.point_features > 0;
  const int input_dim = points ? sim::kProprioDim : sim::StateDim(task);
  if (config.discrete != discrete || config.action_dim != action_dim ||
      config.proprio_dim != input_dim || (points && config.point_features != 4))
    throw core::Error(what + ": a policy for " + std::to_string(config.action_dim) +
                      (config.discrete ? " discrete" : "") + " actions from " +
                      std::to_string(config.proprio_dim) + "-d " +
                      (points ? "proprioception and points" : "state") + "; task '" +
                      task.spec().name + "' needs " + std::to_string(action_dim) +
                      (discrete ? " discrete" : "") + " actions from " + std::to_string(input_dim) +
                      "-d " + (points ? "proprioception and points" : "privileged state"));
}

std::vector<PolicyEpisode> RunPolicyEpisodes(PolicyNet& net, std::shared_ptr<const sim::Task> task,
                                             const PolicyEvalOptions& options, int64_t first,
                                             int64_t count, bool record) {
  const PolicyConfig& config = net->config();
  const bool points = config.point_features > 0;
  const bool discrete = config.discrete;
  std::vector<PolicyEpisode> episodes(count);
  core::ThreadPool pool(options.threads);
  pool.ParallelRanges(count, [&](int block, int64_t begin, int64_t end) {
    torch::NoGradGuard no_grad;
    sim::Env env(task, block);
    const int state_dim = env.state_dim();
    const int input_dim = points ? sim::kProprioDim : state_dim;
    std::unique_ptr<sim::CloudMaker> clouds;
    if (points) {
      sim::CloudMaker::Options cloud_options;
      cloud_options.scene_points = options.scene_points;
      cloud_options.arm_points = options.arm_points;
      cloud_options.noise = task->spec().camera.noise;  // the real sensor's, if calibrated
      clouds = std::make_unique<sim::CloudMaker>(*task, env.model(), cloud_options);
    }
    std::vector<float> scene(3 * options.scene_points), arm(3 * options.arm_points);
    std::vector<float> state(state_dim), proprio(sim::kProprioDim);
    PointSampling sampling;
    sampling.n = config.points;
    torch::Tensor point_input = torch::empty({1, config.points, 4});
    torch::Tensor input = torch::empty({1, input_dim});
    const int horizon = task->spec().horizon;
    for (int64_t j = begin; j < end; ++j) {
      const uint64_t seed = core::MixSeed(options.seed, static_cast<uint64_t>(first + j));
      env.Reset(seed, options.level);
      core::Rng cloud_rng(seed, 0xc1), sample_rng(seed, 0x5a), action_rng(seed, 0xac);
      PolicyEpisode& episode = episodes[j];
      std::optional<EpisodeRecorder> recorder;
      if (record)
        recorder.emplace(
            episode.record, horizon, discrete ? 1 : config.action_dim, state_dim,
            points ? options.scene_points : 0, options.arm_points,
            nlohmann::json{{"seed", seed}, {"level", options.level}, {"episode", first + j}});
      int t = 0;
      for (; t < horizon; ++t) {
        env.State(state.data());
        env.Proprio(proprio.data());
        if (points) {
          clouds->Make(env.model(), env.data(), env.base(), cloud_rng, scene.data(), arm.data());
          SamplePoints(scene.data(), options.scene_points, arm.data(), options.arm_points, sampling,
                       false, sample_rng, point_input.data_ptr<float>());
        }
        std::copy_n(points ? proprio.data() : state.data(), input_dim, input.data_ptr<float>());
        const torch::Tensor out = net->forward(point_input, input);
        const sim::Action action = ChooseAction(net, out, options, action_rng);
        if (recorder)
          recorder->Row(t, action, state, proprio, points ? &scene : nullptr,
                        points ? &arm : nullptr);
        const sim::StepResult r = env.Step(action);
        if (recorder) recorder->Outcome(r);
        if (r.success) {
          episode.steps = t + 1;
          break;
        }
        if (r.done) break;
      }
      if (recorder) recorder->Finish();
    }
  });
  return episodes;
}

PolicyEvalReport EvaluatePolicy(PolicyNet& net, std::shared_ptr<const sim::Task> task,
                                const PolicyEvalOptions& options) {
  const auto start = core::Clock::now();
  net->eval();
  PolicyEvalReport report;
  report.episodes = options.episodes;
  for (const PolicyEpisode& e : RunPolicyEpisodes(net, task, options, 0, options.episodes, false)) {
    report.steps.push_back(e.steps);
    report.successes += e.steps > 0;
  }
  report.seconds = core::SecondsSince(start);
  return report;
}

PolicyNet LoadPolicyFor(const std::filesystem::path& policy, const sim::Task& task) {
  PolicyNet net = LoadPolicy(policy);
  CheckPolicyFitsTask(net->config(), task, policy.string());
  net->eval();
  return net;
}

PolicyEvalReport EvaluatePolicy(const std::filesystem::path& policy,
                                std::shared_ptr<const sim::Task> task,
                                const PolicyEvalOptions& options) {
  PolicyNet net = LoadPolicyFor(policy, *task);
  return EvaluatePolicy(net, std::move(task), options);
}

void TracePolicyEpisode(const std::filesystem::path& policy, std::shared_ptr<const sim::Task> task,
                        const PolicyEvalOptions& options, int64_t episode, std::ostream& out) {
  PolicyNet net = LoadPolicyFor(policy, *task);
  const PolicyEpisode e = RunPolicyEpisodes(net, task, options, episode, 1, true).front();
  const core::Episode& r = e.record;
  auto row = [](const core::FloatArray& a, std::size_t t) {
    return std::vector<float>(a.row(t), a.row(t) + a.row_size());
  };
  for (std::size_t t = 0; t < r.length(); ++t) {
    nlohmann::json j = {{"step", t}, {"action", row(r.actions, t)}};
    if (r.states.rows() > t) j["state"] = row(r.states, t);
    if (r.rewards.size() > t) j["reward"] = r.rewards[t];
    out << j.dump() << "\n";
  }
  out << nlohmann::json{{"success", e.steps > 0}, {"steps", e.steps}}.dump() << "\n";
}

InverseDistillReport InverseDistill(const std::filesystem::path& policy,
                                    std::shared_ptr<const sim::Task> task,
                                    const InverseDistillOptions& options,
                                    const std::filesystem::path& out, core::Progress* progress) {
  const auto start = core::Clock::now();
  if (options.successes <= 0 || options.round <= 0 || options.rollout.episodes <= 0)
    throw core::ConfigError("train inverse-distill", "n",
                            "positive numbers of demos, attempts and episodes per round");
  PolicyNet net = LoadPolicyFor(policy, *task);
  const nlohmann::json env_args = {
      {"env_name", task->spec().name},
      {"type", "twinforge"},
      {"task", task->spec().name},
      {"source", "sim:" + task->spec().scene},
      {"policy", policy.string()},
      {"action_mode", Discrete(*task) ? "discrete" : "continuous"},
      {"level", options.rollout.level},
      {"temperature", options.rollout.sample ? options.rollout.temperature : 0.0},
      {"scene_points", options.rollout.scene_points},
      {"arm_points", options.rollout.arm_points}};
  core::DatasetWriter writer = core::DatasetWriter::Create(out, env_args);
  InverseDistillReport report;
  for (int64_t first = 0; report.successes < options.successes && first < options.rollout.episodes;
       first += options.round) {
    const int64_t count = std::min<int64_t>(options.round, options.rollout.episodes - first);
    for (PolicyEpisode& e : RunPolicyEpisodes(net, task, options.rollout, first, count, true)) {
      ++report.attempts;
      if (e.steps < 0) continue;
      // Every fifth kept demo is held out for validation, as `demos record` does.
      writer.Add(e.record, report.successes % 5 == 4 ? core::Split::kValid : core::Split::kTrain);
      if (++report.successes == options.successes) break;
    }
    if (progress) progress->Set(report.successes, std::to_string(report.attempts) + " attempts");
  }
  report.seconds = core::SecondsSince(start);
  spdlog::info("inverse distillation: {} of {} episodes succeeded ({:.0f}%), {} kept in {}",
               report.successes, report.attempts, 100 * report.success_rate(), report.successes,
               out.string());
  return report;
}

InverseDistillReport ExpertDemos(std::shared_ptr<const sim::Task> task,
                                 const InverseDistillOptions& options,
                                 const std::filesystem::path& out, core::Progress* progress) {
  const auto start = core::Clock::now();
  if (options.successes <= 0 || options.rollout.episodes <= 0)
    throw core::ConfigError("sim demos from the expert", "n",
                            "positive numbers of demos and attempts");
  const bool discrete = Discrete(*task);
  core::DatasetWriter writer =
      core::DatasetWriter::Create(out, {{"env_name", task->spec().name},
                                        {"type", "twinforge"},
                                        {"task", task->spec().name},
                                        {"source", "sim:" + task->spec().scene},
                                        {"policy", "scripted expert"},
                                        {"action_mode", discrete ? "discrete" : "continuous"},
                                        {"level", options.rollout.level}});
  sim::Env env(task);
  sim::ScriptedExpert expert(*task);
  std::vector<float> state(env.state_dim()), proprio(sim::kProprioDim);
  const int horizon = task->spec().horizon;
  InverseDistillReport report;
  for (int64_t e = 0; report.successes < options.successes && e < options.rollout.episodes; ++e) {
    const uint64_t seed = core::MixSeed(options.rollout.seed, static_cast<uint64_t>(e));
    env.Reset(seed, options.rollout.level);
    expert.Reset();
    core::Rng rng(seed, 0xe7);
    core::Episode episode;
    EpisodeRecorder recorder(episode, horizon, discrete ? 1 : sim::kContinuousActionDim,
                             env.state_dim(), 0, 0,
                             {{"seed", seed}, {"level", options.rollout.level}, {"episode", e}});
    bool success = false;
    for (int t = 0; t < horizon && !success; ++t) {
      env.State(state.data());
      env.Proprio(proprio.data());
      // The action as the file stores it (float), so a demo replays exactly as it ran.
      sim::Action action = expert.Act(env, rng);
      for (double& v : action.value) v = static_cast<float>(v);
      recorder.Row(t, action, state, proprio);
      const sim::StepResult r = env.Step(action);
      recorder.Outcome(r);
      success = r.success;
      if (r.done) break;
    }
    recorder.Finish();
    ++report.attempts;
    if (!success) continue;
    writer.Add(episode, report.successes % 5 == 4 ? core::Split::kValid : core::Split::kTrain);
    ++report.successes;
    if (progress) progress->Set(report.successes, std::to_string(report.attempts) + " attempts");
  }
  report.seconds = core::SecondsSince(start);
  spdlog::info("sim demos: the twin's scripted operator succeeded in {} of {} episodes, kept in {}",
               report.successes, report.attempts, out.string());
  return report;
}

}  // namespace twinforge::learn
