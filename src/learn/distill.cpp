#include "learn/distill.h"

#include <Eigen/Geometry>
#include <cmath>
#include <fstream>
#include <numeric>

#include "core/dataset.h"
#include "core/error.h"
#include "core/log.h"
#include "core/measure.h"
#include "core/thread_pool.h"
#include "learn/data_parallel.h"
#include "learn/policy_net.h"
#include "learn/rollout.h"
#include "sim/camera.h"
#include "sim/env.h"

namespace twinforge::learn {

void DistillSource::Append(const DistillSource& other) {
  if (other.size() == 0) return;
  if (size() == 0) {
    const std::string keep = name;
    *this = other;
    if (!keep.empty()) name = keep;
    return;
  }
  if (other.scene_n != scene_n || other.arm_n != arm_n || other.proprio_dim != proprio_dim ||
      other.target_dim != target_dim)
    throw core::Error("distill: cannot add '" + other.name + "' to '" + name +
                      "': their steps differ in shape");
  const auto add = [](std::vector<float>& to, const std::vector<float>& from) {
    to.insert(to.end(), from.begin(), from.end());
  };
  add(scene, other.scene);
  add(arm, other.arm);
  add(proprio, other.proprio);
  add(state, other.state);
  add(target, other.target);
  add(action, other.action);
}

std::vector<std::pair<int, std::size_t>> PlanBatch(const std::vector<const DistillSource*>& sources,
                                                   int batch, core::Rng& rng,
                                                   const std::vector<double>& weights) {
  if (!weights.empty() && weights.size() != sources.size())
    throw core::Error("distill: " + std::to_string(weights.size()) + " batch weights for " +
                      std::to_string(sources.size()) + " sources");
  std::vector<int> filled;
  double total = 0;
  for (int s = 0; s < int(sources.size()); ++s)
    if (sources[s]->size() > 0) {
      filled.push_back(s);
      total += weights.empty() ? 1.0 : weights[s];
    }
  if (filled.empty()) throw core::Error("distill: no data to train on");
  // Whole rows first, then the rest by largest remainder (ties to the earlier source: sources
  // of the same weight get bit-identical remainders, so no tolerance is needed to see a tie).
  const int k = static_cast<int>(filled.size());
  std::vector<int> share(k);
  std::vector<double> rest(k);
  int given = 0;
  for (int i = 0; i < k; ++i) {
    const double exact = batch * (weights.empty() ? 1.0 : weights[filled[i]]) / total;
    share[i] = static_cast<int>(std::floor(exact + 1e-9));
    rest[i] = exact - share[i];
    given += share[i];
  }
  std::vector<int> order(k);
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return rest[a] > rest[b]; });
  for (int i = 0; given < batch; ++i, ++given) ++share[order[i % k]];
  std::vector<std::pair<int, std::size_t>> rows;
  rows.reserve(batch);
  for (int i = 0; i < k; ++i) {
    const DistillSource& source = *sources[filled[i]];
    for (int r = 0; r < share[i]; ++r)
      rows.emplace_back(filled[i], static_cast<std::size_t>(rng.Index(source.size())));
  }
  return rows;
}

void PerturbScene(float* points, int n, double shift, double tilt_deg, core::Rng& rng) {
  if (shift <= 0 && tilt_deg <= 0) return;
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  int count = 0;
  for (int i = 0; i < n; ++i)
    if (points[4 * i + 3] == 0.f) {
      centroid += Eigen::Vector3d(points[4 * i], points[4 * i + 1], points[4 * i + 2]);
      ++count;
    }
  if (count == 0) return;
  centroid /= count;
  Eigen::Vector3d axis(rng.Normal(), rng.Normal(), rng.Normal());
  if (axis.norm() < 1e-9) axis = Eigen::Vector3d::UnitZ();
  const double angle = rng.Normal() * tilt_deg * M_PI / 180;
  const Eigen::Matrix3d R = Eigen::AngleAxisd(angle, axis.normalized()).toRotationMatrix();
  const Eigen::Vector3d t(rng.Normal() * shift, rng.Normal() * shift, rng.Normal() * shift);
  for (int i = 0; i < n; ++i) {
    if (points[4 * i + 3] != 0.f) continue;
    Eigen::Vector3d p(points[4 * i], points[4 * i + 1], points[4 * i + 2]);
    p = R * (p - centroid) + centroid + t;
    for (int k = 0; k < 3; ++k) points[4 * i + k] = static_cast<float>(p[k]);
  }
}

DistillSource LoadDemoSource(const std::filesystem::path& demos) {
  core::DatasetReader reader(demos);
  const bool discrete = reader.env_args().value("action_mode", "discrete") == "discrete";
  DistillSource source;
  source.name = "real";
  for (const std::string& name : reader.demos()) {
    const core::Episode e = reader.Read(name);
    const std::string where = demos.string() + ":data/" + name;
    for (const char* key : {"proprio", "scene_points", "arm_points"})
      if (!e.obs.count(key)) throw core::DatasetError(where + ": no obs/" + key);
    const auto& proprio = e.obs.at("proprio");
    const auto& scene = e.obs.at("scene_points");
    const auto& arm = e.obs.at("arm_points");
    DistillSource d;
    d.name = "real";
    d.scene_n = int(scene.row_size() / 3);
    d.arm_n = int(arm.row_size() / 3);
    d.proprio_dim = int(proprio.row_size());
    d.action_dim = int(e.actions.row_size());
    d.target_dim = discrete ? sim::kDiscreteActions : d.action_dim;
    d.scene = scene.data;
    d.arm = arm.data;
    d.proprio = proprio.data;
    d.action = e.actions.data;
    for (std::size_t t = 0; t < e.length(); ++t) {
      std::vector<float> target(d.target_dim, 0.f);
      if (discrete) {
        const float a = e.actions.row(t)[0];
        if (!(a >= 0 && a < sim::kDiscreteActions) || a != std::floor(a))
          throw core::DatasetError(where + "/actions row " + std::to_string(t) +
                                   ": not a move index 0.." +
                                   std::to_string(sim::kDiscreteActions - 1));
        target[int(a)] = 1.f;
      } else {
        std::copy_n(e.actions.row(t), d.target_dim, target.begin());
      }
      d.target.insert(d.target.end(), target.begin(), target.end());
    }
    source.Append(d);
  }
  if (source.size() == 0) throw core::DatasetError(demos.string() + ": no demo steps");
  return source;
}

DistillCollection CollectDistill(PolicyNet& teacher, PolicyNet* actor,
                                 std::shared_ptr<const sim::Task> task,
                                 const DistillRollout& options, int64_t first, int64_t count) {
  const PolicyConfig& tc = teacher->config();
  const bool discrete = tc.discrete;
  const int target_dim = tc.action_dim;
  const bool student_acts = actor != nullptr;
  struct Kept {
    DistillSource data;
    bool success = false, kept = false;
  };
  std::vector<Kept> episodes(count);
  core::ThreadPool pool(options.threads);
  pool.ParallelRanges(count, [&](int block, int64_t begin, int64_t end) {
    torch::NoGradGuard no_grad;
    sim::Env env(task, block);
    const int state_dim = env.state_dim();
    sim::CloudMaker::Options cloud_options;
    cloud_options.scene_points = options.scene_points;
    cloud_options.arm_points = options.arm_points;
    cloud_options.rendered = options.rendered;
    cloud_options.noise = task->spec().camera.noise;  // the real sensor's, if calibrated
    sim::CloudMaker clouds(*task, env.model(), cloud_options);
    std::vector<float> scene(3 * options.scene_points), arm(3 * options.arm_points);
    std::vector<float> state(state_dim), proprio(sim::kProprioDim);
    PointSampling sampling;
    sampling.n = options.student_points;
    torch::Tensor points = torch::empty({1, sampling.n, 4});
    torch::Tensor state_in = torch::empty({1, state_dim});
    torch::Tensor proprio_in = torch::empty({1, sim::kProprioDim});
    PolicyEvalOptions choose;
    choose.sample = options.sample;
    const int horizon = task->spec().horizon;
    for (int64_t j = begin; j < end; ++j) {
      const uint64_t seed = core::MixSeed(options.seed, static_cast<uint64_t>(first + j));
      env.Reset(seed, options.level);
      core::Rng cloud_rng(seed, 0xc1), sample_rng(seed, 0x5a), action_rng(seed, 0xac);
      DistillSource& d = episodes[j].data;
      d.scene_n = options.scene_points;
      d.arm_n = options.arm_points;
      d.proprio_dim = sim::kProprioDim;
      d.state_dim = state_dim;
      d.target_dim = target_dim;
      d.action_dim = discrete ? 1 : target_dim;
      for (int t = 0; t < horizon; ++t) {
        env.State(state.data());
        env.Proprio(proprio.data());
        clouds.Make(env.model(), env.data(), env.base(), cloud_rng, scene.data(), arm.data());
        std::copy(state.begin(), state.end(), state_in.data_ptr<float>());
        const torch::Tensor label = teacher->forward(torch::Tensor(), state_in);
        torch::Tensor acted = label;
        if (student_acts) {
          SamplePoints(scene.data(), options.scene_points, arm.data(), options.arm_points, sampling,
                       false, sample_rng, points.data_ptr<float>());
          std::copy(proprio.begin(), proprio.end(), proprio_in.data_ptr<float>());
          acted = (*actor)->forward(points, proprio_in);
        }
        const sim::Action action =
            ChooseAction(student_acts ? *actor : teacher, acted, choose, action_rng);
        d.scene.insert(d.scene.end(), scene.begin(), scene.end());
        d.arm.insert(d.arm.end(), arm.begin(), arm.end());
        d.proprio.insert(d.proprio.end(), proprio.begin(), proprio.end());
        d.state.insert(d.state.end(), state.begin(), state.end());
        const torch::Tensor t_out = discrete ? torch::softmax(label[0], 0) : label[0];
        d.target.insert(d.target.end(), t_out.data_ptr<float>(),
                        t_out.data_ptr<float>() + target_dim);
        if (discrete)
          d.action.push_back(float(action.index));
        else
          for (int k = 0; k < target_dim; ++k) d.action.push_back(float(action.value[k]));
        const sim::StepResult r = env.Step(action);
        if (r.success) {
          episodes[j].success = true;
          break;
        }
        if (r.done) break;
      }
      episodes[j].kept = episodes[j].success || options.keep_failures;
      if (!episodes[j].kept) d = DistillSource();
    }
  });
  DistillCollection out;
  out.episodes = static_cast<int>(count);
  for (Kept& e : episodes) {
    out.successes += e.success;
    if (!e.kept) continue;
    ++out.kept;
    out.data.Append(e.data);
  }
  return out;
}

namespace {

// Loss of the student's outputs against `targets`: cross-entropy with the teacher's move
// probabilities, or the Gaussian negative log-likelihood of the teacher's mean.
torch::Tensor DistillLoss(PolicyNet& net, const torch::Tensor& out, const torch::Tensor& targets) {
  if (net->config().discrete) return -(targets * torch::log_softmax(out, 1)).sum(1).mean();
  return -net->LogProb(out, targets).mean();
}

struct Batch {
  torch::Tensor points, proprio, targets;
};

Batch MakeBatch(const std::vector<const DistillSource*>& sources,
                const std::vector<std::pair<int, std::size_t>>& rows, const DistillOptions& o,
                int proprio_dim, int target_dim, core::Rng& rng) {
  const PointSampling& sampling = o.sampling;
  const auto B = static_cast<int64_t>(rows.size());
  Batch b{torch::empty({B, sampling.n, 4}), torch::empty({B, proprio_dim}),
          torch::empty({B, target_dim})};
  for (int64_t i = 0; i < B; ++i) {
    const DistillSource& s = *sources[rows[i].first];
    const std::size_t t = rows[i].second;
    SamplePoints(s.scene.data() + 3 * s.scene_n * t, s.scene_n, s.arm.data() + 3 * s.arm_n * t,
                 s.arm_n, sampling, true, rng, b.points[i].data_ptr<float>());
    PerturbScene(b.points[i].data_ptr<float>(), sampling.n, o.scene_shift, o.scene_tilt_deg, rng);
    std::copy_n(s.proprio.data() + proprio_dim * t, proprio_dim, b.proprio[i].data_ptr<float>());
    std::copy_n(s.target.data() + target_dim * t, target_dim, b.targets[i].data_ptr<float>());
  }
  return b;
}

}  // namespace

std::vector<DistillStage> DistillStages(const DistillOptions& o) {
  std::vector<DistillStage> stages = {
      {"synthetic", o.synthetic_episodes, o.level, false, false},
      {"rendered", o.rendered_episodes, o.level, true, false},
      {"distractors", o.distractor_episodes, std::max(o.level, 2), true, false}};
  for (int r = 0; r < o.dagger_rounds; ++r)
    stages.push_back({"dagger" + std::to_string(r + 1), o.dagger_episodes, o.level, true, true});
  return stages;
}

DistillRollout DistillStageRollout(const DistillOptions& o, std::size_t k) {
  const DistillStage stage = DistillStages(o).at(k);
  DistillRollout rollout;
  rollout.level = stage.level;
  rollout.rendered = stage.rendered;
  rollout.keep_failures = stage.dagger;
  rollout.sample = stage.dagger ? o.student_sample : o.teacher_sample;
  rollout.scene_points = o.scene_points;
  rollout.arm_points = o.arm_points;
  rollout.student_points = o.sampling.n;
  rollout.seed = core::MixSeed(o.seed, 0x5747 + k);
  rollout.threads = o.threads;
  return rollout;
}

DistillReport TrainDistill(const std::filesystem::path& teacher_path,
                           std::shared_ptr<const sim::Task> task, const std::filesystem::path& real,
                           const std::filesystem::path& out, const DistillOptions& options,
                           core::Progress* progress) {
  const auto start = core::Clock::now();
  PolicyNet teacher = LoadPolicy(teacher_path);
  if (teacher->config().point_features != 0)
    throw core::Error(teacher_path.string() +
                      ": a point-cloud policy; distillation needs a state teacher (`train rl`)");
  CheckPolicyFitsTask(teacher->config(), *task, teacher_path.string());
  teacher->eval();

  torch::manual_seed(options.seed);
  core::Rng rng(options.seed, 0xd157);
  PolicyConfig config;
  config.points = options.sampling.n;
  config.proprio_dim = sim::kProprioDim;
  config.action_dim = teacher->config().action_dim;
  config.discrete = teacher->config().discrete;
  config.action_scale = teacher->config().action_scale;
  config.hidden = options.hidden;
  PolicyNet student(config);
  CheckPolicyFitsTask(config, *task, "the student");
  torch::optim::AdamW optimizer(student->parameters(),
                                torch::optim::AdamWOptions(options.learning_rate));
  DataParallel parallel(student, kGradientShards, options.threads);

  // Sources: the real demos first (when co-training), then one per stage as it runs.
  std::vector<DistillSource> sources;
  sources.reserve(5);
  DistillReport report;
  if (!real.empty()) {
    sources.push_back(LoadDemoSource(real));
    const DistillSource& r = sources.back();
    if (r.proprio_dim != sim::kProprioDim || r.target_dim != config.action_dim)
      throw core::DatasetError(real.string() + ": demos of " + std::to_string(r.target_dim) +
                               " actions from " + std::to_string(r.proprio_dim) +
                               "-d proprioception; the teacher has " +
                               std::to_string(config.action_dim));
    report.real_steps = static_cast<long>(r.size());
    spdlog::info(
        "distill: co-training with {} real steps from {} ({})", report.real_steps, real.string(),
        options.real_weight == 1.0
            ? std::string("an equal share of each batch")
            : fmt::format("{:g} of a sim source's share of each batch", options.real_weight));
  } else {
    spdlog::info("distill: sim data only (no real demos to co-train with)");
  }

  report.curve = out;
  report.curve.replace_extension(".curve.csv");
  if (report.curve.has_parent_path())
    std::filesystem::create_directories(report.curve.parent_path());
  std::ofstream curve(report.curve);
  if (!curve) throw core::IoError("cannot write " + report.curve.string());
  curve << "stage,episodes,successes,kept,steps,loss,student_success,seconds\n";

  const std::vector<DistillStage> stages = DistillStages(options);
  std::size_t last = stages.size();  // the last stage that runs
  for (std::size_t k = 0; k < stages.size(); ++k)
    if (stages[k].episodes > 0) last = k;
  const bool select = options.eval_episodes > 0;

  // A stage's row goes to the curve once its student is scored (or cannot be).
  auto finish_row = [&](const DistillStageReport& sr) {
    curve << sr.name << "," << sr.episodes << "," << sr.successes << "," << sr.kept << ","
          << sr.steps << "," << sr.loss << "," << sr.student << "," << sr.seconds << "\n"
          << std::flush;
  };
  double best = -1;
  auto score = [&](DistillStageReport& sr, double rate, const std::string& how) {
    sr.student = rate;
    spdlog::info("distill: {}: the student succeeds {}% in the twin ({})", sr.name,
                 int(std::lround(100 * rate)), how);
    if (rate > best) {
      best = rate;
      SavePolicy(student, out);
    }
  };
  bool trained = false;  // some stage had data to train on
  for (std::size_t k = 0; k < stages.size(); ++k) {
    const DistillStage& stage = stages[k];
    if (stage.episodes == 0) continue;
    const auto stage_start = core::Clock::now();
    student->eval();
    DistillCollection got = CollectDistill(teacher, stage.dagger ? &student : nullptr, task,
                                           DistillStageRollout(options, k), 0, stage.episodes);
    student->train();
    // The stage before's row awaits its score (only the last stage's is written at once). The
    // student acting in a DAgger round is the one that stage trained: its episodes score it.
    if (!report.stages.empty()) {
      DistillStageReport& before = report.stages.back();
      if (stage.dagger && select)
        score(before, double(got.successes) / got.episodes,
              fmt::format("{} of {} episodes of {}", got.successes, got.episodes, stage.name));
      finish_row(before);
    }
    DistillStageReport sr;
    sr.name = stage.name;
    sr.episodes = got.episodes;
    sr.successes = got.successes;
    sr.kept = got.kept;
    sr.steps = static_cast<long>(got.data.size());
    got.data.name = stage.dagger ? "dagger" : stage.name;
    // DAgger rounds share one source: their data are one kind, relabelled student states.
    if (stage.dagger && !sources.empty() && sources.back().name == "dagger")
      sources.back().Append(got.data);
    else
      sources.push_back(std::move(got.data));
    spdlog::info("distill: {}: {} of {} episodes succeeded ({} acting), {} steps kept", stage.name,
                 sr.successes, sr.episodes, stage.dagger ? "student" : "teacher", sr.steps);

    std::vector<const DistillSource*> from;
    std::vector<double> weights;  // the real demos' relative share
    bool any_data = false;
    for (const DistillSource& s : sources) {
      const bool is_real = !real.empty() && from.empty();  // the real demos come first
      from.push_back(&s);
      weights.push_back(is_real ? options.real_weight : 1.0);
      any_data = any_data || s.size() > 0;
    }
    // Without real demos, a teacher that succeeds in none of a stage's episodes leaves nothing to
    // learn from yet; DAgger, which keeps every step, will.
    if (!any_data)
      spdlog::warn("distill: {}: no data yet (no teacher success, no real demos); no training",
                   stage.name);
    trained = trained || any_data;
    double recent = 0;
    int recent_n = 0;
    for (int step = 0; any_data && step < options.train_steps; ++step) {
      const Batch b = MakeBatch(from, PlanBatch(from, options.batch, rng, weights), options,
                                config.proprio_dim, config.action_dim, rng);
      const double loss =
          parallel.Backward(b.points.size(0), [&](PolicyNet& net, int64_t i, int64_t j) {
            return DistillLoss(net, net->forward(b.points.slice(0, i, j), b.proprio.slice(0, i, j)),
                               b.targets.slice(0, i, j));
          });
      torch::nn::utils::clip_grad_norm_(student->parameters(), options.grad_clip);
      optimizer.step();
      if (step >= options.train_steps - 100) {
        recent += loss;
        ++recent_n;
      }
    }
    sr.loss = recent_n ? recent / recent_n : NAN;
    spdlog::info("distill: {}: loss {:.3f}", stage.name, sr.loss);
    report.stages.push_back(sr);
    if (k == last && select) {
      PolicyEvalOptions eval;
      eval.episodes = options.eval_episodes;
      eval.level = options.level;
      eval.seed = options.eval_seed;
      eval.threads = options.threads;
      eval.sample = options.student_sample;
      const double rate = EvaluatePolicy(student, task, eval).success_rate();
      student->train();
      score(report.stages.back(), rate,
            fmt::format("{} evaluation episodes of its own", options.eval_episodes));
    }
    report.stages.back().seconds = core::SecondsSince(stage_start);
    if (k == last) finish_row(report.stages.back());
    if (progress) progress->Advance(1, stage.name);
  }
  if (report.stages.empty()) throw core::ConfigError("train distill", "episodes", "no stage ran");
  if (!trained)
    throw core::Error(
        "distill: no data to train on: the teacher succeeded in none of its episodes, there are "
        "no real demos and no DAgger round ran");
  if (best < 0) SavePolicy(student, out);  // nothing scored: the last student
  report.seconds = core::SecondsSince(start);
  return report;
}

}  // namespace twinforge::learn
