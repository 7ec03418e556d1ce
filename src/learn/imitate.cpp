#include "learn/imitate.h"

#include <algorithm>
#include <fstream>
#include <mutex>

#include "core/error.h"
#include "core/log.h"
#include "core/measure.h"
#include "core/rng.h"
#include "core/thread_pool.h"
#include "learn/policy_net.h"
#include "learn/rollout.h"
#include "sim/env.h"
#include "sim/expert.h"

namespace twinforge::learn {
namespace {

// Labelled steps: the privileged state seen and the expert's action there (a move index, or the
// continuous action's components).
struct Labelled {
  int state_dim = 0, label_dim = 0;
  std::vector<float> states, labels;
  std::size_t size() const { return state_dim ? states.size() / state_dim : 0; }
};

// Episodes 0 .. count - 1 of a round seeded `seed`: the expert (patient) acts with its action
// perturbed by `noise` (sim::PerturbAction), and each state is labelled with the action it chose
// there. Episode i starts as `sim expert`'s episode i of that seed; the steps are appended in
// episode order, whatever the thread count. Fills the round's successes and plans, and advances
// `progress` (if any) an episode at a time.
void Gather(std::shared_ptr<const sim::Task> task, const ImitationOptions& options, uint64_t seed,
            int64_t count, Labelled& data, ImitationRound& row, core::Progress* progress) {
  const double noise = options.noise;
  const bool discrete = task->spec().control.action == sim::ActionMode::kDiscrete;
  std::vector<Labelled> per_episode(count);
  std::vector<char> success(count, 0);
  core::ThreadPool pool(options.threads);
  std::vector<sim::PlanCounts> plans(pool.size());
  std::mutex progress_mutex;
  pool.ParallelRanges(count, [&](int block, int64_t begin, int64_t end) {
    sim::Env env(task, block);
    sim::ScriptedExpert expert(*task);
    expert.set_patient(true);
    expert.set_planning(options.plan);
    const int state_dim = env.state_dim();
    for (int64_t j = begin; j < end; ++j) {
      core::Rng rng = sim::BeginExpertEpisode(env, expert, seed, j, options.level);
      Labelled& out = per_episode[j];
      out.state_dim = state_dim;
      out.label_dim = discrete ? 1 : sim::kContinuousActionDim;
      for (int t = 0; t < task->spec().horizon; ++t) {
        out.states.resize(out.states.size() + state_dim);
        float* state = out.states.data() + out.states.size() - state_dim;
        env.State(state);
        const sim::Action label = expert.Act(env, rng);
        if (discrete)
          out.labels.push_back(float(label.index));
        else
          for (double v : label.value) out.labels.push_back(float(v));
        const sim::StepResult r = env.Step(
            noise > 0 ? sim::PerturbAction(label, task->spec().control.limits, noise, rng) : label);
        if (r.success) {
          success[j] = 1;
          break;
        }
        if (r.done) break;
      }
      if (progress) {
        const std::lock_guard<std::mutex> lock(progress_mutex);
        progress->Advance();
      }
    }
    plans[block] = expert.plans();
  });
  for (const sim::PlanCounts& p : plans) row.plans += p;
  int successes = 0;
  for (int64_t j = 0; j < count; ++j) {
    data.state_dim = per_episode[j].state_dim;
    data.label_dim = per_episode[j].label_dim;
    data.states.insert(data.states.end(), per_episode[j].states.begin(),
                       per_episode[j].states.end());
    data.labels.insert(data.labels.end(), per_episode[j].labels.begin(),
                       per_episode[j].labels.end());
    successes += success[j];
  }
  row.successes = successes;
}

// The state's normalization from `data`: its mean and standard deviation, at least `floor`.
void FitNormalization(PolicyNet& net, const Labelled& data, double floor) {
  const torch::Tensor s =
      torch::from_blob(const_cast<float*>(data.states.data()),
                       {int64_t(data.size()), int64_t(data.state_dim)}, torch::kFloat);
  torch::NoGradGuard no_grad;
  net->obs_mean.copy_(s.mean(0));
  net->obs_std.copy_(s.std(0).clamp_min(floor));
}

// `steps` Adam steps on batches drawn from all of `data`; returns the mean loss of the last 100.
double Train(PolicyNet& net, torch::optim::Adam& adam, const Labelled& data, int steps, int batch,
             core::Rng& rng) {
  const bool discrete = net->config().discrete;
  const int64_t n = int64_t(data.size());
  const torch::Tensor states = torch::from_blob(const_cast<float*>(data.states.data()),
                                                {n, int64_t(data.state_dim)}, torch::kFloat);
  const torch::Tensor labels = torch::from_blob(const_cast<float*>(data.labels.data()),
                                                {n, int64_t(data.label_dim)}, torch::kFloat);
  net->train();
  std::vector<int64_t> pick(batch);
  double tail = 0;
  int tail_n = 0;
  for (int step = 1; step <= steps; ++step) {
    for (auto& k : pick) k = int64_t(rng.Index(uint64_t(n)));
    const torch::Tensor rows = torch::from_blob(pick.data(), {batch}, torch::kLong);
    const torch::Tensor out = net->forward({}, states.index_select(0, rows));
    const torch::Tensor y = labels.index_select(0, rows);
    const torch::Tensor loss =
        discrete ? torch::nn::functional::cross_entropy(out, y.view(-1).to(torch::kLong))
                 : ((out - y) / net->ActionScale()).pow(2).sum(1).mean();
    adam.zero_grad();
    loss.backward();
    torch::nn::utils::clip_grad_norm_(net->parameters(), 5.0);
    adam.step();
    if (step > steps - 100) {
      tail += loss.item<double>();
      ++tail_n;
    }
  }
  net->eval();
  return tail_n ? tail / tail_n : NAN;
}

}  // namespace

ImitationReport TrainImitation(std::shared_ptr<const sim::Task> task,
                               const std::filesystem::path& out, const ImitationOptions& options,
                               core::Progress* progress) {
  const auto start = core::Clock::now();
  const sim::TaskSpec& spec = task->spec();
  if (spec.expert.steps.empty())
    throw core::Error("train imitate: task " + spec.name +
                      " has no scripted expert (expert: steps) to label the states");
  const bool discrete = spec.control.action == sim::ActionMode::kDiscrete;
  PolicyConfig config;
  config.point_features = 0;
  config.proprio_dim = sim::StateDim(*task);
  config.action_dim = discrete ? sim::kDiscreteActions : sim::kContinuousActionDim;
  config.discrete = discrete;
  config.hidden = options.hidden;
  if (!discrete) config.action_scale = ContinuousActionScale(spec.control.limits);
  torch::manual_seed(options.seed);
  PolicyNet net(config);
  torch::optim::Adam adam(net->parameters(), torch::optim::AdamOptions(options.learning_rate));
  core::Rng rng(options.seed, 0x1717);

  if (out.has_parent_path()) std::filesystem::create_directories(out.parent_path());
  ImitationReport report;
  report.curve = out;
  report.curve += ".curve.csv";
  std::ofstream curve(report.curve);
  if (!curve) throw core::IoError(report.curve.string() + ": cannot write the curve");
  curve << "round,episodes,successes,steps,loss,learner_success,seconds\n";
  PolicyEvalOptions eval;
  eval.episodes = options.eval_episodes;
  eval.level = options.level;
  eval.seed = options.eval_seed;
  eval.threads = options.threads;
  double best = -1;
  Labelled data;
  for (int round = 0; round < options.rounds; ++round) {
    ImitationRound row;
    row.round = round;
    row.episodes = options.episodes;
    const uint64_t seed = core::MixSeed(options.seed, uint64_t(round));
    Gather(task, options, seed, row.episodes, data, row, progress);
    if (round == 0) FitNormalization(net, data, options.std_floor);
    row.steps = long(data.size());
    row.loss = Train(net, adam, data, options.train_steps, options.batch, rng);
    if (options.eval_episodes > 0) row.learner = EvaluatePolicy(net, task, eval).success_rate();
    row.seconds = core::SecondsSince(start);
    if (options.eval_episodes == 0 || row.learner > best) {
      best = row.learner;
      report.best_round = round;
      SavePolicy(net, out);
    }
    curve << row.round << "," << row.episodes << "," << row.successes << "," << row.steps << ","
          << row.loss << "," << row.learner << "," << row.seconds << "\n";
    curve.flush();
    spdlog::info(
        "imitate: round {}, the expert succeeded in {} of {} noisy episodes; {} labelled steps, "
        "loss {:.4f}, learner {:.0f}% in the twin",
        round, row.successes, row.episodes, row.steps, row.loss, 100 * row.learner);
    report.rounds.push_back(row);
    if (progress)
      progress->Advance(0, "learner " + std::to_string(int(std::lround(100 * row.learner))) + "%");
  }
  report.seconds = core::SecondsSince(start);
  return report;
}

StateActor LoadStateActor(const std::filesystem::path& file, const sim::Task& task) {
  auto net = std::make_shared<PolicyNet>(LoadPolicyFor(file, task));
  if ((*net)->config().point_features > 0)
    throw core::Error(file.string() +
                      ": a point-cloud policy; the actor needs a state policy "
                      "(train imitate, train rl)");
  return [net](const sim::Env& env) {
    torch::NoGradGuard no_grad;
    torch::Tensor input = torch::empty({1, env.state_dim()});
    env.State(input.data_ptr<float>());
    if (spdlog::should_log(spdlog::level::debug)) {
      // Inputs far outside the states it was taught on: the actor is guessing there.
      const torch::Tensor z = ((input[0] - (*net)->obs_mean) / (*net)->obs_std).abs();
      for (int64_t k = 0; k < z.size(0); ++k)
        if (z[k].item<float>() > 4)
          spdlog::debug("state actor: input {} is {:.3f}, {:.1f} sd from its teaching states", k,
                        input[0][k].item<float>(), z[k].item<float>());
    }
    core::Rng unused(0);
    return ChooseAction(*net, (*net)->forward({}, input), PolicyEvalOptions{}, unused);
  };
}

}  // namespace twinforge::learn
