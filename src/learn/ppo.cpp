#include "learn/ppo.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <numeric>
#include <sstream>

#include "core/config.h"
#include "core/dataset.h"
#include "core/error.h"
#include "core/fs.h"
#include "core/log.h"
#include "core/measure.h"
#include "core/plot.h"
#include "core/rng.h"
#include "learn/bench.h"
#include "learn/policy_net.h"
#include "learn/ppo_update.h"
#include "learn/rollout.h"
#include "sim/env.h"
#include "sim/vec_env.h"

namespace twinforge::learn {

namespace {

using core::Clock;
using core::SecondsSince;

// Streams of the per-iteration generators.
enum Stream : uint64_t {
  kEnvSeeds = 1,
  kActions = 2,
  kShuffle = 3,
  kDemoBatches = 4,
  kPretrainBatches = 5
};

// SB3's RunningMeanStd: mean and variance of every state seen, merged a batch at a time.
struct RunningNorm {
  double count = 1e-4;
  std::vector<double> mean, var;
  explicit RunningNorm(int dim = 0) : mean(dim, 0.0), var(dim, 1.0) {}
  void Update(const torch::Tensor& rows) {  // [n, dim] float
    const auto n = static_cast<double>(rows.size(0));
    const torch::Tensor r = rows.to(torch::kDouble);
    const torch::Tensor m = r.mean(0), v = r.var(0, false);
    const double total = count + n;
    for (std::size_t k = 0; k < mean.size(); ++k) {
      const double bm = m[k].item<double>(), bv = v[k].item<double>();
      const double delta = bm - mean[k];
      mean[k] += delta * n / total;
      var[k] = (var[k] * count + bv * n + delta * delta * count * n / total) / total;
    }
    count = total;
  }
  void CopyTo(PolicyNet& net) const {
    torch::NoGradGuard no_grad;
    for (std::size_t k = 0; k < mean.size(); ++k) {
      net->obs_mean[k] = mean[k];
      net->obs_std[k] = std::sqrt(var[k] + 1e-8);
    }
  }
};

struct CurveRow {
  int iteration = 0;
  int64_t env_steps = 0;
  double seconds = 0, rollout_success = 0, eval_success = NAN;
  double policy_loss = 0, value_loss = 0, bc_loss = NAN, entropy = 0, approx_kl = 0;
  double update_samples_per_s = 0;
};

nlohmann::json RowJson(const CurveRow& r) {
  const auto num = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(); };
  return {r.iteration,       r.env_steps,           r.seconds,
          r.rollout_success, num(r.eval_success),   r.policy_loss,
          r.value_loss,      num(r.bc_loss),        r.entropy,
          r.approx_kl,       r.update_samples_per_s};
}

CurveRow RowFromJson(const nlohmann::json& j) {
  const auto num = [](const nlohmann::json& v) { return v.is_null() ? NAN : v.get<double>(); };
  CurveRow r;
  r.iteration = j[0];
  r.env_steps = j[1];
  r.seconds = j[2];
  r.rollout_success = j[3];
  r.eval_success = num(j[4]);
  r.policy_loss = j[5];
  r.value_loss = j[6];
  r.bc_loss = num(j[7]);
  r.entropy = j[8];
  r.approx_kl = j[9];
  r.update_samples_per_s = j[10];
  return r;
}

void WriteCurve(const std::vector<CurveRow>& rows, const std::filesystem::path& csv,
                const std::filesystem::path& svg, const std::string& name) {
  const auto tmp = csv.string() + ".tmp";
  {
    std::ofstream out(tmp);
    if (!out) throw core::IoError("cannot write " + csv.string());
    out << "iteration,env_steps,seconds,rollout_success,eval_success,policy_loss,value_loss,"
           "bc_loss,entropy,approx_kl,update_samples_per_s\n";
    const auto cell = [](double v) { return std::isfinite(v) ? std::to_string(v) : std::string(); };
    for (const CurveRow& r : rows)
      out << r.iteration << "," << r.env_steps << "," << r.seconds << "," << r.rollout_success
          << "," << cell(r.eval_success) << "," << r.policy_loss << "," << r.value_loss << ","
          << cell(r.bc_loss) << "," << r.entropy << "," << r.approx_kl << ","
          << r.update_samples_per_s << "\n";
    if (!out) throw core::IoError("cannot write " + csv.string());
  }
  std::filesystem::rename(tmp, csv);
  core::PlotSeries by_steps[2], by_time[2];
  by_steps[0].name = by_time[0].name = "training rollouts (sampled)";
  by_steps[1].name = by_time[1].name = "evaluation";
  for (const CurveRow& r : rows) {
    for (int k = 0; k < 2; ++k) {
      by_steps[k].x.push_back(double(r.env_steps));
      by_time[k].x.push_back(r.seconds / 60);
    }
    by_steps[0].y.push_back(r.rollout_success);
    by_time[0].y.push_back(r.rollout_success);
    by_steps[1].y.push_back(r.eval_success);
    by_time[1].y.push_back(r.eval_success);
  }
  core::WriteSvgPlot(
      svg,
      {{name + ": success vs env steps", "env steps", "success", {by_steps[0], by_steps[1]}, true},
       {name + ": success vs wall-clock", "minutes", "success", {by_time[0], by_time[1]}, true}});
}

// The options that change what training computes: budgets, threads and evaluation do not, so a
// run may be resumed with those changed.
nlohmann::json Fingerprint(nlohmann::json options) {
  for (const char* k : {"threads", "max_seconds", "max_env_steps", "max_iterations",
                        "target_success", "eval_every", "eval_episodes", "eval_seed", "eval_sample",
                        "demos",         // a file's path, which checkpoints before stop 28 held
                        "init_policy"})  // its path: its content is fingerprinted
    options.erase(k);
  return options;
}

nlohmann::json Fingerprint(const PpoOptions& options, const sim::Task& task,
                           const std::filesystem::path& demos) {
  nlohmann::json j = Fingerprint(core::ToJson(options));
  j["task"] = task.spec().name;
  j["scene"] = task.spec().scene;
  // What the task is, not only its name: a twin rebuilt, recalibrated or re-identified under the
  // same paths is another task. The compiled model holds the scene's geometry and physics.
  const mjModel* m = task.model();
  std::string model(mj_sizeModel(m), '\0');
  mj_saveModel(m, nullptr, model.data(), static_cast<int>(model.size()));
  j["task_content"] = core::Fingerprint().Add(core::ToJson(task.spec()).dump()).Add(model).Hex();
  // What the demos file holds, not where it is: demos remade under the same name are other
  // demos, and a run directory moved or copied elsewhere keeps its teacher's checkpoint.
  j["demos_content"] = demos.empty() ? "" : core::Fingerprint().AddFile(demos).Hex();
  if (!options.init_policy.empty())
    j["init_content"] = core::Fingerprint().AddFile(options.init_policy).Hex();
  return j;
}

// "seed 1 -> 99, demos a -> b": what differs between two fingerprints.
std::string Differences(const nlohmann::json& before, const nlohmann::json& now) {
  std::string out;
  for (const auto& [key, value] : now.items()) {
    const nlohmann::json old = before.contains(key) ? before[key] : nlohmann::json();
    if (old != value)
      out += (out.empty() ? "" : ", ") + key + " " + old.dump() + " -> " + value.dump();
  }
  return out.empty() ? "a checkpoint of another kind" : out;
}

DemoSteps LoadSimDemos(const std::filesystem::path& path, int state_dim, bool discrete) {
  core::DatasetReader reader(path);
  std::vector<float> states, actions;
  int64_t rows = 0, action_dim = 0;
  for (const std::string& name : reader.demos()) {
    const core::Episode e = reader.Read(name);
    const std::string where = path.string() + ":data/" + name;
    if (e.states.empty())
      throw core::DatasetError(where +
                               ": no privileged `states` (make the demos with `train "
                               "inverse-distill`)");
    if (int(e.states.row_size()) != state_dim)
      throw core::DatasetError(where + "/states: " + std::to_string(e.states.row_size()) +
                               " values per step; this task's state has " +
                               std::to_string(state_dim));
    action_dim = static_cast<int64_t>(e.actions.row_size());
    if (discrete && action_dim != 1)
      throw core::DatasetError(where + "/actions: expected one move index per step");
    states.insert(states.end(), e.states.data.begin(), e.states.data.end());
    actions.insert(actions.end(), e.actions.data.begin(), e.actions.data.end());
    rows += static_cast<int64_t>(e.length());
  }
  if (rows == 0) throw core::DatasetError(path.string() + ": no demo steps");
  DemoSteps d;
  d.states = torch::from_blob(states.data(), {rows, state_dim}).clone();
  d.actions = torch::from_blob(actions.data(), {rows, action_dim}).clone();
  if (discrete) d.actions = d.actions.view({-1}).to(torch::kLong);
  return d;
}

void SaveCheckpoint(const std::filesystem::path& path, PpoModel& model, const RunningNorm& norm,
                    const RunningNorm& return_norm, const nlohmann::json& state) {
  PolicyNet& policy = model.policy;
  torch::nn::Sequential& value = model.value;
  torch::optim::Adam& optimizer = *model.optimizer;
  torch::serialize::OutputArchive archive, p, v, o;
  policy->save(p);
  value->save(v);
  optimizer.save(o);
  archive.write("policy", p);
  archive.write("value", v);
  archive.write("optimizer", o);
  archive.write("norm_mean", torch::tensor(norm.mean, torch::kDouble));
  archive.write("norm_var", torch::tensor(norm.var, torch::kDouble));
  archive.write("norm_count", torch::tensor(norm.count, torch::kDouble));
  archive.write("return_mean", torch::tensor(return_norm.mean, torch::kDouble));
  archive.write("return_var", torch::tensor(return_norm.var, torch::kDouble));
  archive.write("return_count", torch::tensor(return_norm.count, torch::kDouble));
  archive.write("twinforge_ppo_state", c10::IValue(state.dump()));
  const auto tmp = path.string() + ".tmp";
  archive.save_to(tmp);
  std::filesystem::rename(tmp, path);
}

// A checkpoint file, read once: its archive, and its state text (fingerprint, counters), which is
// null if the file is not a twinforge PPO checkpoint or cannot be read at all.
struct Checkpoint {
  torch::serialize::InputArchive archive;
  nlohmann::json state;
  std::string error;  // why `state` is null
};

std::unique_ptr<Checkpoint> ReadCheckpoint(const std::filesystem::path& path) {
  auto checkpoint = std::make_unique<Checkpoint>();
  try {
    checkpoint->archive.load_from(path.string());
    c10::IValue text;
    if (!checkpoint->archive.try_read("twinforge_ppo_state", text))
      checkpoint->error = "not a twinforge PPO checkpoint";
    else
      checkpoint->state = nlohmann::json::parse(text.toStringRef());
  } catch (const c10::Error& e) {
    checkpoint->error = std::string("unreadable checkpoint (") + e.what_without_backtrace() + ")";
  } catch (const nlohmann::json::exception& e) {
    checkpoint->error = std::string("unreadable state (") + e.what() + ")";
  }
  return checkpoint;
}

// Restores weights, optimizer and normalizers from a checkpoint whose state was read.
void RestoreCheckpoint(const std::filesystem::path& path, Checkpoint& checkpoint, PpoModel& model,
                       RunningNorm& norm, RunningNorm& return_norm) {
  torch::serialize::InputArchive& archive = checkpoint.archive;
  try {
    torch::serialize::InputArchive p, v, o;
    archive.read("policy", p);
    archive.read("value", v);
    archive.read("optimizer", o);
    model.policy->load(p);
    model.value->load(v);
    model.optimizer->load(o);
    torch::Tensor mean, var, count;
    archive.read("norm_mean", mean);
    archive.read("norm_var", var);
    archive.read("norm_count", count);
    if (mean.numel() != int64_t(norm.mean.size()))
      throw core::Error(path.string() + ": normalizer of another state size");
    for (std::size_t k = 0; k < norm.mean.size(); ++k) {
      norm.mean[k] = mean[k].item<double>();
      norm.var[k] = var[k].item<double>();
    }
    norm.count = count.item<double>();
    torch::Tensor return_mean, return_var, return_count;
    // The returns' mean moves their variance at every update: without it (checkpoints before
    // stop 30 lack it) a resumed run scales its rewards differently from an uninterrupted one.
    if (archive.try_read("return_mean", return_mean))
      return_norm.mean[0] = return_mean[0].item<double>();
    else
      spdlog::warn(
          "rl: {} holds no return mean (an older checkpoint); the run resumes, but not "
          "exactly as it would have gone on",
          path.string());
    archive.read("return_var", return_var);
    archive.read("return_count", return_count);
    return_norm.var[0] = return_var[0].item<double>();
    return_norm.count = return_count.item<double>();
  } catch (const c10::Error& e) {
    throw core::Error(path.string() + ": unreadable checkpoint (" + e.what_without_backtrace() +
                      "); delete it or pass --fresh");
  }
}

// Samples `n` demo steps with `rng`: their raw states and actions.
std::pair<torch::Tensor, torch::Tensor> DemoBatch(const DemoSteps& demos, int n, core::Rng& rng) {
  std::vector<int64_t> pick(n);
  for (auto& k : pick) k = static_cast<int64_t>(rng.Index(demos.states.size(0)));
  const torch::Tensor di = torch::from_blob(pick.data(), {n}, torch::kLong);
  return {demos.states.index_select(0, di), demos.actions.index_select(0, di)};
}

// The smallest standard deviation the normalizer starts from when it starts from the demos
// (state units: m, quaternion components, m of finger travel).
constexpr double kDemoStdFloor = 0.1;

// BC alone on the demos, before any rollout, with its own Adam at PPO's rate. The normalizer
// starts from the demos' states, so the imitation and PPO's first rollout see states alike.
// Returns the mean loss of the last 100 steps.
double PretrainOnDemos(PolicyNet& policy, const DemoSteps& demos, RunningNorm& norm,
                       const PpoOptions& options, core::Progress* progress) {
  norm.Update(demos.states);
  // A value the demos hold nearly still (a top-down tool's tilt) would otherwise be scaled by
  // hundreds: the policy's first small tilt becomes a clipped input it never saw. Peg, 200
  // operator demos, greedy success at level 1 over 50 episodes: no floor 18%, 0.02 12%, 0.1 38%,
  // 0.2 38%.
  for (double& v : norm.var) v = std::max(v, kDemoStdFloor * kDemoStdFloor);
  norm.CopyTo(policy);
  policy->train();
  torch::optim::Adam adam(policy->parameters(),
                          torch::optim::AdamOptions(options.learning_rate).eps(1e-5));
  core::Rng rng(core::MixSeed(options.seed, 0), kPretrainBatches);
  double tail = 0;
  int tail_n = 0;
  for (int step = 1; step <= options.bc_pretrain_steps; ++step) {
    const auto [states, actions] = DemoBatch(demos, options.bc_pretrain_batch, rng);
    const torch::Tensor loss = -policy->LogProb(policy->forward({}, states), actions).mean();
    adam.zero_grad();
    loss.backward();
    torch::nn::utils::clip_grad_norm_(policy->parameters(), options.max_grad_norm);
    adam.step();
    if (step > options.bc_pretrain_steps - 100) {
      tail += loss.item<double>();
      ++tail_n;
    }
    if (progress && step % 500 == 0)
      progress->Set(0, "BC pretraining " + std::to_string(step) + "/" +
                           std::to_string(options.bc_pretrain_steps));
  }
  return tail_n ? tail / tail_n : NAN;
}

// Starts `policy` from the state policy in `options.init_policy` (its weights and normalization,
// which `norm` takes over; see PpoOptions). Throws Error naming the file when it does not fit.
void InitFromPolicy(PolicyNet& policy, RunningNorm& norm, const PpoOptions& options) {
  const std::string& path = options.init_policy;
  PolicyNet from = LoadPolicy(path);
  const PolicyConfig& a = from->config();
  const PolicyConfig& b = policy->config();
  if (a.point_features != 0 || a.proprio_dim != b.proprio_dim || a.action_dim != b.action_dim ||
      a.discrete != b.discrete || a.hidden != b.hidden || a.action_scale != b.action_scale)
    throw core::Error(path + ": not a state policy of this task with " + std::to_string(b.hidden) +
                      "-wide layers (reads " + std::to_string(a.proprio_dim) + " values, " +
                      (a.point_features ? "points, " : "") + "acts in " +
                      std::to_string(a.action_dim) + "; this task's state has " +
                      std::to_string(b.proprio_dim) + ", its actions " +
                      std::to_string(b.action_dim) + ")");
  torch::NoGradGuard no_grad;
  const auto source = from->named_parameters(true);
  for (auto& item : policy->named_parameters(true)) item.value().copy_(source[item.key()]);
  const auto buffers = from->named_buffers(true);
  for (auto& item : policy->named_buffers(true)) item.value().copy_(buffers[item.key()]);
  if (!b.discrete) policy->log_std.copy_((options.init_std * policy->ActionScale()).log());
  for (std::size_t k = 0; k < norm.mean.size(); ++k) {
    norm.mean[k] = policy->obs_mean[k].item<double>();
    const double sd = policy->obs_std[k].item<double>();
    norm.var[k] = sd * sd - 1e-8;
  }
}

torch::nn::Sequential ValueNet(int in, int hidden) {
  torch::nn::Linear out(hidden, 1);
  {
    torch::NoGradGuard no_grad;
    out->weight.mul_(0.1);
    out->bias.zero_();
  }
  return torch::nn::Sequential(torch::nn::Linear(in, hidden), torch::nn::Tanh(),
                               torch::nn::Linear(hidden, hidden), torch::nn::Tanh(), out);
}

torch::Tensor Entropy(const PolicyNet& net, const torch::Tensor& out) {
  if (net->config().discrete) {
    const torch::Tensor logp = torch::log_softmax(out, 1);
    return -(logp.exp() * logp).sum(1).mean();
  }
  return (net->log_std + 0.5 * std::log(2 * M_PI * M_E)).sum();
}

}  // namespace

PpoModel::PpoModel(const PolicyConfig& config, const PpoOptions& options)
    : policy(config), value(ValueNet(config.proprio_dim, options.hidden)) {
  params = policy->parameters();
  for (const auto& p : value->parameters()) params.push_back(p);
  optimizer = std::make_unique<torch::optim::Adam>(
      params, torch::optim::AdamOptions(options.learning_rate).eps(1e-5));
}

MinibatchStats PpoMinibatch(PpoModel& model, const PpoOptions& options, const torch::Tensor& obs,
                            const torch::Tensor& actions, const torch::Tensor& old_logp,
                            const torch::Tensor& advantages, const torch::Tensor& returns,
                            const DemoSteps* demos, core::Rng& demo_rng, bool value_only) {
  PolicyNet& policy = model.policy;
  const auto step = [&](const torch::Tensor& loss) {
    model.optimizer->zero_grad();
    loss.backward();
    torch::nn::utils::clip_grad_norm_(model.params, options.max_grad_norm);
    model.optimizer->step();
  };
  MinibatchStats stats;
  const torch::Tensor v = model.value->forward(obs).view({-1});
  const torch::Tensor value_loss = (returns - v).pow(2).mean();
  stats.value_loss = value_loss.item<double>();
  if (value_only) {
    step(options.value_coef * value_loss);
    return stats;
  }
  const torch::Tensor o = policy->ForwardNormalized({}, obs);
  const torch::Tensor logp = policy->LogProb(o, actions);
  const torch::Tensor adv = (advantages - advantages.mean()) / (advantages.std() + 1e-8);
  const torch::Tensor ratio = (logp - old_logp).exp();
  const torch::Tensor policy_loss =
      -torch::min(ratio * adv, ratio.clamp(1 - options.clip, 1 + options.clip) * adv).mean();
  const torch::Tensor entropy = Entropy(policy, o);
  torch::Tensor loss =
      policy_loss + options.value_coef * value_loss - options.entropy_coef * entropy;
  if (demos) {
    const auto [states, demo_actions] = DemoBatch(*demos, options.bc_batch, demo_rng);
    const torch::Tensor bc = -policy->LogProb(policy->forward({}, states), demo_actions).mean();
    loss = loss + options.bc_coef * bc;
    stats.bc_loss = bc.item<double>();
  }
  step(loss);
  stats.policy_loss = policy_loss.item<double>();
  stats.entropy = entropy.item<double>();
  torch::NoGradGuard no_grad;
  stats.approx_kl = ((ratio - 1) - ratio.log()).mean().item<double>();
  return stats;
}

PpoReport TrainPpo(std::shared_ptr<const sim::Task> task, const std::filesystem::path& demos,
                   const std::filesystem::path& out, const PpoOptions& options,
                   CheckpointMode checkpoint, core::Progress* progress) {
  const auto session_start = Clock::now();
  // Command-line options do not pass through the config reader's checks.
  if (!options.init_policy.empty() && options.bc_pretrain_steps > 0)
    throw core::ConfigError("train rl", "init_policy",
                            "either a policy to start from (--init) or BC pretraining "
                            "(--bc-pretrain-steps), not both");
  const sim::TaskSpec& spec = task->spec();
  const bool discrete = spec.control.action == sim::ActionMode::kDiscrete;
  const int state_dim = sim::StateDim(*task);
  const int horizon = spec.horizon;
  const int N = options.num_envs;
  const int64_t samples = int64_t(N) * horizon;

  torch::manual_seed(options.seed);
  PolicyConfig config;
  config.point_features = 0;
  config.proprio_dim = state_dim;
  config.action_dim = discrete ? sim::kDiscreteActions : sim::kContinuousActionDim;
  config.discrete = discrete;
  config.hidden = options.hidden;
  if (!discrete) config.action_scale = ContinuousActionScale(spec.control.limits);
  PpoModel model(config, options);
  PolicyNet& policy = model.policy;
  torch::nn::Sequential& value = model.value;
  RunningNorm norm(state_dim);
  // SB3's reward normalization: rewards divided by the running standard deviation of the
  // discounted return. Unscaled, a success held for 40 steps is a return of ~40, the value loss
  // (~50) dominates the shared gradient-norm clip and the policy barely moves (KL ~0.003).
  RunningNorm return_norm(1);

  const bool use_demos = !demos.empty() && options.bc_coef > 0;
  DemoSteps demo;
  if (use_demos) demo = LoadSimDemos(demos, state_dim, discrete);

  PpoReport report;
  report.demo_steps = use_demos ? static_cast<int>(demo.states.size(0)) : 0;
  std::filesystem::path base = out;
  base.replace_extension();
  report.checkpoint = base.string() + ".ckpt";
  report.curve_csv = base.string() + ".curve.csv";
  report.curve_svg = base.string() + ".curve.svg";
  if (out.has_parent_path()) std::filesystem::create_directories(out.parent_path());

  const nlohmann::json fingerprint = Fingerprint(options, *task, demos);
  std::vector<CurveRow> rows;
  int iteration = 0;
  int64_t env_steps = 0;
  double seconds_before = 0;
  report.best_eval_success = -1;
  if (checkpoint == CheckpointMode::kStartOver) std::filesystem::remove(report.checkpoint);
  std::unique_ptr<Checkpoint> stored_checkpoint;
  if (std::filesystem::exists(report.checkpoint))
    stored_checkpoint = ReadCheckpoint(report.checkpoint);
  if (checkpoint == CheckpointMode::kResumeOrStartOver && stored_checkpoint) {
    // Only its state text is compared: a checkpoint of other inputs may not even restore.
    const nlohmann::json& state = stored_checkpoint->state;
    const nlohmann::json stored =
        state.is_object() ? Fingerprint(state.value("fingerprint", nlohmann::json::object()))
                          : nlohmann::json();
    if (stored != fingerprint) {
      spdlog::info("rl: {} was made from other inputs ({}); the teacher starts over",
                   report.checkpoint.string(),
                   state.is_object() ? Differences(stored, fingerprint) : stored_checkpoint->error);
      stored_checkpoint.reset();
      std::filesystem::remove(report.checkpoint);
    }
  }
  if (stored_checkpoint) {
    if (!stored_checkpoint->state.is_object())
      throw core::Error(report.checkpoint.string() + ": " + stored_checkpoint->error +
                        "; delete it or pass --fresh");
    const nlohmann::json& state = stored_checkpoint->state;
    const nlohmann::json stored = Fingerprint(state.value("fingerprint", nlohmann::json::object()));
    if (stored != fingerprint)
      throw core::Error(report.checkpoint.string() +
                        ": made with another task, demos or options (" +
                        Differences(stored, fingerprint) + "); pass --fresh to start over");
    RestoreCheckpoint(report.checkpoint, *stored_checkpoint, model, norm, return_norm);
    iteration = state["iteration"];
    env_steps = state["env_steps"];
    seconds_before = state["seconds"];
    report.best_eval_success = state["best_eval_success"];
    report.best_iteration = state["best_iteration"];
    for (const auto& r : state["rows"]) rows.push_back(RowFromJson(r));
    report.resumed_from = iteration;
    if (progress) progress->ResumeAt(iteration);
    spdlog::info("rl: resuming {} at iteration {} ({} env steps)", report.checkpoint.string(),
                 iteration, env_steps);
  }
  spdlog::info(
      "rl: task {} level {}, {} envs x {} steps per iteration, {} demo steps for BC, "
      "{} + {} parameters",
      spec.name, options.level, N, horizon, report.demo_steps, ParameterCount(*policy),
      ParameterCount(*value));
  {
    std::string budget;
    const auto add = [&](bool on, const std::string& what) {
      if (on) budget += (budget.empty() ? "" : ", ") + what;
    };
    add(options.max_iterations > 0, std::to_string(options.max_iterations) + " iterations");
    add(options.max_env_steps > 0, std::to_string(options.max_env_steps) + " env steps");
    add(options.max_seconds > 0, fmt::format("{:.1f} min of wall clock", options.max_seconds / 60));
    spdlog::info("rl: budget {}; target {:.2f}", budget.empty() ? "none" : budget,
                 options.target_success);
  }

  sim::VecEnvOptions vec_options;
  vec_options.num_envs = N;
  vec_options.threads = options.threads;
  vec_options.level = options.level;
  sim::VecEnv vec(task, vec_options);

  // Rollout buffers, allocated once.
  const torch::Tensor raw = torch::empty({horizon, N, state_dim});
  torch::Tensor obs = torch::empty({horizon, N, state_dim});
  torch::Tensor actions = discrete ? torch::empty({horizon, N}, torch::kLong)
                                   : torch::empty({horizon, N, config.action_dim});
  torch::Tensor logps = torch::empty({horizon, N}), values = torch::empty({horizon + 1, N});
  torch::Tensor rewards = torch::empty({horizon, N}), dones = torch::empty({horizon, N});
  torch::Tensor discounted = torch::empty({horizon, N});  // running discounted returns
  std::vector<sim::Action> step_actions(N);
  std::vector<double> update_rates;

  PolicyEvalOptions eval_options;
  eval_options.episodes = options.eval_episodes;
  eval_options.level = options.level;
  eval_options.seed = options.eval_seed;
  eval_options.threads = options.threads;
  eval_options.sample = options.eval_sample;

  const auto elapsed = [&] { return seconds_before + SecondsSince(session_start); };
  const auto budget_left = [&]() -> std::string {
    if (options.max_iterations > 0 && iteration >= options.max_iterations) return "iterations";
    if (options.max_env_steps > 0 && env_steps >= options.max_env_steps) return "env_steps";
    if (options.max_seconds > 0 && elapsed() >= options.max_seconds) return "seconds";
    return "";
  };
  report.stopped_by = budget_left();
  if (!rows.empty() && std::isfinite(rows.back().eval_success) &&
      rows.back().eval_success >= options.target_success)
    report.stopped_by = "target";

  // The curve, then the checkpoint that makes it the run's state.
  const auto commit = [&] {
    WriteCurve(rows, report.curve_csv, report.curve_svg, spec.name);
    nlohmann::json state = {{"fingerprint", fingerprint},
                            {"iteration", iteration},
                            {"env_steps", env_steps},
                            {"seconds", rows.back().seconds},
                            {"best_eval_success", report.best_eval_success},
                            {"best_iteration", report.best_iteration},
                            {"rows", nlohmann::json::array()}};
    for (const CurveRow& r : rows) state["rows"].push_back(RowJson(r));
    SaveCheckpoint(report.checkpoint, model, norm, return_norm, state);
  };

  // Iteration 0, when PPO starts from a policy (another run's, or BC's on the demos): its own
  // evaluation, as the first row and the best so far.
  const bool from_policy = !options.init_policy.empty();
  const bool pretrain = use_demos && options.bc_pretrain_steps > 0;
  if (!stored_checkpoint && (from_policy || pretrain)) {
    CurveRow row;
    if (from_policy)
      InitFromPolicy(policy, norm, options);
    else
      row.bc_loss = report.pretrain_bc_loss =
          PretrainOnDemos(policy, demo, norm, options, progress);
    row.eval_success = report.pretrain_eval_success =
        EvaluatePolicy(policy, task, eval_options).success_rate();
    report.best_eval_success = row.eval_success;
    SavePolicy(policy, out);
    row.seconds = elapsed();
    rows.push_back(row);
    commit();
    if (from_policy)
      spdlog::info("rl: starting from {}: evaluation success {:.2f}", options.init_policy,
                   row.eval_success);
    else
      spdlog::info("rl: BC pretraining, {} steps: loss {:.3f}, evaluation success {:.2f}",
                   options.bc_pretrain_steps, row.bc_loss, row.eval_success);
    if (row.eval_success >= options.target_success) report.stopped_by = "target";
  }

  while (report.stopped_by.empty()) {
    ++iteration;
    const auto iteration_start = Clock::now();
    norm.CopyTo(policy);
    policy->eval();
    vec.Reset(core::MixSeed(options.seed, core::MixSeed(iteration, kEnvSeeds)));
    core::Rng action_rng(core::MixSeed(options.seed, iteration), kActions);
    int finished = 0, succeeded = 0;
    const float reward_scale = float(1.0 / std::sqrt(return_norm.var[0] + 1e-8));
    std::vector<float> ret(N, 0.0f);
    {
      torch::NoGradGuard no_grad;
      for (int t = 0; t < horizon; ++t) {
        const torch::Tensor s = torch::from_blob(const_cast<float*>(vec.states()), {N, state_dim});
        raw[t].copy_(s);
        obs[t].copy_(policy->Normalize(s));
        const torch::Tensor o = policy->ForwardNormalized({}, obs[t]);
        values[t].copy_(value->forward(obs[t]).view({-1}));
        if (discrete) {
          const torch::Tensor prob = torch::softmax(o, 1).contiguous();
          const float* p = prob.data_ptr<float>();
          int64_t* a = actions[t].data_ptr<int64_t>();
          for (int i = 0; i < N; ++i) {
            a[i] = SampleIndex(p + i * config.action_dim, config.action_dim, action_rng);
            step_actions[i] = sim::Action::Discrete(static_cast<int>(a[i]));
          }
        } else {
          const torch::Tensor mean = o.contiguous();
          float* a = actions[t].data_ptr<float>();
          for (int i = 0; i < N; ++i) {
            step_actions[i] = SampleGaussian(mean.data_ptr<float>() + i * config.action_dim,
                                             policy->log_std.data_ptr<float>(), 1.0, action_rng);
            for (int k = 0; k < config.action_dim; ++k)
              a[i * config.action_dim + k] = float(step_actions[i].value[k]);
          }
        }
        logps[t].copy_(policy->LogProb(o, actions[t]));
        vec.Step(step_actions.data());
        float* reward_row = rewards[t].data_ptr<float>();
        float* done_row = dones[t].data_ptr<float>();
        float* return_row = discounted[t].data_ptr<float>();
        for (int i = 0; i < N; ++i) {
          ret[i] = float(options.gamma) * ret[i] + vec.rewards()[i];
          return_row[i] = ret[i];
          reward_row[i] = vec.rewards()[i] * reward_scale;
          done_row[i] = float(vec.dones()[i]);
          if (vec.dones()[i]) ret[i] = 0;
          if (vec.dones()[i]) {
            ++finished;
            succeeded += vec.episode_success()[i];
          }
        }
      }
      const torch::Tensor s = torch::from_blob(const_cast<float*>(vec.states()), {N, state_dim});
      values[horizon].copy_(value->forward(policy->Normalize(s)).view({-1}));
    }
    env_steps += samples;
    // GAE(lambda); an episode's end (horizon or instability) is terminal.
    torch::Tensor advantages = torch::empty({horizon, N});
    {
      const float* r = rewards.data_ptr<float>();
      const float* d = dones.data_ptr<float>();
      const float* v = values.data_ptr<float>();
      float* adv = advantages.data_ptr<float>();
      std::vector<float> next(N, 0.0f);
      for (int t = horizon - 1; t >= 0; --t)
        for (int i = 0; i < N; ++i) {
          const float keep = 1.0f - d[t * N + i];
          const float delta =
              r[t * N + i] + float(options.gamma) * v[(t + 1) * N + i] * keep - v[t * N + i];
          next[i] = delta + float(options.gamma * options.lambda) * keep * next[i];
          adv[t * N + i] = next[i];
        }
    }
    const torch::Tensor returns = (advantages + values.slice(0, 0, horizon)).view({-1});
    const torch::Tensor flat_obs = obs.view({samples, state_dim});
    const torch::Tensor flat_actions =
        discrete ? actions.view({-1}) : actions.view({samples, config.action_dim});
    const torch::Tensor flat_logp = logps.view({-1}), flat_adv = advantages.view({-1});

    // PPO epochs.
    const auto update_start = Clock::now();
    policy->train();
    core::Rng shuffle_rng(core::MixSeed(options.seed, iteration), kShuffle);
    core::Rng demo_rng(core::MixSeed(options.seed, iteration), kDemoBatches);
    std::vector<int64_t> order(samples);
    std::iota(order.begin(), order.end(), 0);
    const int64_t mb = (samples + options.minibatches - 1) / options.minibatches;
    const bool value_only = iteration <= options.critic_warmup;
    CurveRow row;
    int updates = 0;
    double bc_total = 0;
    for (int epoch = 0; epoch < options.epochs; ++epoch) {
      shuffle_rng.Shuffle(order);
      for (int64_t at = 0; at < samples; at += mb) {
        const int64_t n = std::min(mb, samples - at);
        const torch::Tensor idx = torch::from_blob(order.data() + at, {n}, torch::kLong);
        const MinibatchStats m = PpoMinibatch(
            model, options, flat_obs.index_select(0, idx), flat_actions.index_select(0, idx),
            flat_logp.index_select(0, idx), flat_adv.index_select(0, idx),
            returns.index_select(0, idx), use_demos ? &demo : nullptr, demo_rng, value_only);
        ++updates;
        row.policy_loss += m.policy_loss;
        row.value_loss += m.value_loss;
        row.entropy += m.entropy;
        row.approx_kl += m.approx_kl;
        bc_total += m.bc_loss;
      }
    }
    const double update_seconds = SecondsSince(update_start);
    if (!from_policy) norm.Update(raw.view({samples, state_dim}));
    return_norm.Update(discounted.view({samples, 1}));
    row.iteration = iteration;
    row.env_steps = env_steps;
    row.rollout_success = finished ? double(succeeded) / finished : 0.0;
    row.policy_loss /= updates;
    row.value_loss /= updates;
    row.entropy /= updates;
    row.approx_kl /= updates;
    row.bc_loss = use_demos && !value_only ? bc_total / updates : NAN;
    row.update_samples_per_s = double(samples) * options.epochs / update_seconds;
    update_rates.push_back(row.update_samples_per_s);

    const bool last_by_budget = !budget_left().empty();
    if (iteration % options.eval_every == 0 || last_by_budget) {
      const PolicyEvalReport eval = EvaluatePolicy(policy, task, eval_options);
      row.eval_success = eval.success_rate();
      if (row.eval_success > report.best_eval_success) {
        report.best_eval_success = row.eval_success;
        report.best_iteration = iteration;
        SavePolicy(policy, out);
      }
    }
    row.seconds = elapsed();
    rows.push_back(row);
    commit();
    std::ostringstream note;
    note.precision(2);
    note << "success " << row.rollout_success;
    if (std::isfinite(row.eval_success)) note << ", eval " << row.eval_success;
    note << ", " << std::lround(SecondsSince(iteration_start) * 10) / 10.0 << " s/it";
    if (progress) progress->Set(iteration, note.str());
    spdlog::debug("rl: iteration {} {}", iteration, note.str());
    if (std::isfinite(row.eval_success) && row.eval_success >= options.target_success)
      report.stopped_by = "target";
    else
      report.stopped_by = budget_left();
  }
  report.iterations = iteration;
  report.env_steps = env_steps;
  report.seconds = elapsed();
  if (!update_rates.empty()) {
    report.update_samples_per_s = core::Median(update_rates);
    report.matmul_peak_gflops = MatmulPeakGflops(3);
    report.update_share_of_matmul_peak =
        report.update_samples_per_s * PpoSampleFlops(state_dim, options.hidden, config.action_dim) /
        1e9 / report.matmul_peak_gflops;
  }
  if (report.best_eval_success < 0) {  // no evaluation ran: keep the last weights
    SavePolicy(policy, out);
    report.best_iteration = iteration;
  }
  report.best_eval_success = std::max(0.0, report.best_eval_success);
  return report;
}

}  // namespace twinforge::learn
