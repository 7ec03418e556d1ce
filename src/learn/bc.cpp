#include "learn/bc.h"

#include <algorithm>
#include <fstream>
#include <numeric>

#include "core/dataset.h"
#include "core/error.h"
#include "core/log.h"
#include "core/measure.h"
#include "learn/data_parallel.h"
#include "learn/policy_net.h"
#include "sim/action.h"
#include "sim/camera.h"

namespace twinforge::learn {

void SamplePoints(const float* scene, int scene_n, const float* arm, int arm_n,
                  const PointSampling& sampling, bool augment, core::Rng& rng, float* out) {
  const int total = scene_n + arm_n;
  if (total <= 0) throw core::Error("an observation with no points");
  // Every point as (x, y, z, is_arm).
  std::vector<float> all(4 * std::size_t(total));
  for (int k = 0; k < total; ++k) {
    const bool is_arm = k >= scene_n;
    std::copy_n(is_arm ? arm + 3 * (k - scene_n) : scene + 3 * k, 3, all.data() + 4 * k);
    all[4 * k + 3] = is_arm ? 1.f : 0.f;
  }
  int keep = total;
  if (augment)
    keep = std::max(1, static_cast<int>(std::lround(
                           total * (1 - rng.Uniform(sampling.drop_min, sampling.drop_max)))));
  if (keep < total) {
    std::vector<float> kept(4 * std::size_t(keep));
    sim::ResamplePoints(all.data(), total, keep, rng, kept.data(), 4);
    all.swap(kept);
  }
  sim::ResamplePoints(all.data(), keep, sampling.n, rng, out, 4);
  if (augment)
    for (int i = 0; i < sampling.n; ++i)
      for (int j = 0; j < 3; ++j)
        out[4 * i + j] += static_cast<float>(rng.Normal() * sampling.jitter);
}

namespace {

struct Sample {
  const core::Episode* episode;
  std::size_t t;
};

struct Data {
  std::vector<core::Episode> episodes;
  std::vector<Sample> train, valid;
  int proprio_dim = 0, action_dim = 0;
  bool discrete = true;
};

const core::FloatArray& Obs(const core::Episode& e, const std::string& key,
                            const std::string& where) {
  const auto it = e.obs.find(key);
  if (it == e.obs.end()) throw core::DatasetError(where + ": no obs/" + key);
  return it->second;
}

Data LoadDemos(const std::filesystem::path& path) {
  core::DatasetReader reader(path);
  Data data;
  const std::string mode = reader.env_args().value("action_mode", "discrete");
  data.discrete = mode == "discrete";
  std::vector<std::string> valid = reader.Mask("valid");
  const auto& names = reader.demos();
  if (names.empty()) throw core::DatasetError(path.string() + ": no demos");
  if (valid.empty() && names.size() >= 2)
    for (std::size_t i = 4; i < names.size(); i += 5) valid.push_back(names[i]);
  if (valid.empty() && names.size() >= 2) valid.push_back(names.back());
  data.episodes.reserve(names.size());
  for (const auto& name : names) {
    data.episodes.push_back(reader.Read(name));
    const core::Episode& e = data.episodes.back();
    const std::string where = path.string() + ":data/" + name;
    const auto& proprio = Obs(e, "proprio", where);
    Obs(e, "scene_points", where);
    Obs(e, "arm_points", where);
    if (data.proprio_dim == 0) {
      data.proprio_dim = static_cast<int>(proprio.row_size());
      data.action_dim = data.discrete ? sim::kDiscreteActions : int(e.actions.row_size());
    }
    const bool is_valid = std::find(valid.begin(), valid.end(), name) != valid.end();
    for (std::size_t t = 0; t < e.length(); ++t) {
      if (data.discrete) {
        const float a = e.actions.row(t)[0];
        if (!(a >= 0 && a < sim::kDiscreteActions) || a != std::floor(a))
          throw core::DatasetError(where + "/actions row " + std::to_string(t) +
                                   ": not a move index 0.." +
                                   std::to_string(sim::kDiscreteActions - 1));
      }
      (is_valid ? data.valid : data.train).push_back({&e, t});
    }
  }
  if (data.train.empty()) throw core::DatasetError(path.string() + ": no training steps");
  return data;
}

struct Batch {
  torch::Tensor points, proprio, actions;
};

Batch MakeBatch(const std::vector<Sample>& samples, const std::vector<std::size_t>& rows,
                const PointSampling& sampling, bool augment, bool discrete, core::Rng& rng) {
  const auto B = static_cast<int64_t>(rows.size());
  const auto& first = *samples[rows[0]].episode;
  const int64_t P = static_cast<int64_t>(first.obs.at("proprio").row_size());
  const int64_t A = discrete ? 1 : static_cast<int64_t>(first.actions.row_size());
  Batch b{torch::empty({B, sampling.n, 4}), torch::empty({B, P}), torch::empty({B, A})};
  for (int64_t i = 0; i < B; ++i) {
    const Sample& s = samples[rows[i]];
    const auto& scene = s.episode->obs.at("scene_points");
    const auto& arm = s.episode->obs.at("arm_points");
    SamplePoints(scene.row(s.t), int(scene.row_size() / 3), arm.row(s.t), int(arm.row_size() / 3),
                 sampling, augment, rng, b.points[i].data_ptr<float>());
    std::copy_n(s.episode->obs.at("proprio").row(s.t), P, b.proprio[i].data_ptr<float>());
    std::copy_n(s.episode->actions.row(s.t), A, b.actions[i].data_ptr<float>());
  }
  if (discrete) b.actions = b.actions.view({-1});
  return b;
}

struct Scores {
  double loss = 0, metric = 0;
};

// Mean loss and metric over `samples`, without augmentation, the points drawn with a fixed seed.
Scores Evaluate(PolicyNet& net, const std::vector<Sample>& samples, const PointSampling& sampling,
                bool discrete) {
  torch::NoGradGuard no_grad;
  net->eval();
  core::Rng rng(12345);
  Scores s;
  for (std::size_t start = 0; start < samples.size(); start += 256) {
    std::vector<std::size_t> rows;
    for (std::size_t i = start; i < std::min(samples.size(), start + 256); ++i) rows.push_back(i);
    const Batch b = MakeBatch(samples, rows, sampling, false, discrete, rng);
    const torch::Tensor out = net->forward(b.points, b.proprio);
    s.loss += -net->LogProb(out, b.actions).sum().item<double>();
    if (discrete)
      s.metric += out.argmax(1).eq(b.actions.to(torch::kLong)).sum().item<double>();
    else
      s.metric += (out - b.actions).pow(2).mean(1).sum().item<double>();
  }
  s.loss /= double(samples.size());
  s.metric /= double(samples.size());
  net->train();
  return s;
}

}  // namespace

BcReport TrainBc(const std::filesystem::path& demos, const std::filesystem::path& out,
                 const BcOptions& options, core::Progress* progress) {
  const auto start = core::Clock::now();
  const Data data = LoadDemos(demos);
  torch::manual_seed(options.seed);
  core::Rng rng(options.seed);
  PolicyConfig config;
  config.points = options.sampling.n;
  config.proprio_dim = data.proprio_dim;
  config.action_dim = data.action_dim;
  config.discrete = data.discrete;
  config.hidden = options.hidden;
  if (!data.discrete) {
    // The demos' largest value per component (at least 1 mm or mrad): no task file is at hand.
    config.action_scale.assign(data.action_dim, 1e-3);
    for (const core::Episode& e : data.episodes)
      for (std::size_t t = 0; t < e.length(); ++t)
        for (int k = 0; k < data.action_dim; ++k)
          config.action_scale[k] =
              std::max<double>(config.action_scale[k], std::abs(e.actions.row(t)[k]));
  }
  PolicyNet net(config);
  torch::optim::Adam optimizer(net->parameters(), torch::optim::AdamOptions(options.learning_rate));
  DataParallel parallel(net, kGradientShards, options.threads);
  const std::vector<Sample>& held_out = data.valid.empty() ? data.train : data.valid;

  BcReport report;
  report.train_samples = static_cast<int>(data.train.size());
  report.valid_samples = static_cast<int>(data.valid.size());
  report.curve = out;
  report.curve.replace_extension(".curve.csv");
  if (report.curve.has_parent_path())
    std::filesystem::create_directories(report.curve.parent_path());
  std::ofstream curve(report.curve);
  if (!curve) throw core::IoError("cannot write " + report.curve.string());
  curve << "epoch,train_loss,valid_loss," << (data.discrete ? "valid_accuracy" : "valid_mse")
        << "\n";
  spdlog::info("bc: {} train / {} valid steps, {} parameters, {} actions", data.train.size(),
               data.valid.size(), ParameterCount(*net), data.discrete ? "discrete" : "continuous");

  std::vector<std::size_t> order(data.train.size());
  std::iota(order.begin(), order.end(), 0);
  double best = std::numeric_limits<double>::infinity();
  Scores best_scores;
  for (int epoch = 1; epoch <= options.max_epochs; ++epoch) {
    rng.Shuffle(order);
    double total = 0;
    for (std::size_t at = 0; at < order.size(); at += options.batch) {
      const std::vector<std::size_t> rows(
          order.begin() + at, order.begin() + std::min(order.size(), at + options.batch));
      const Batch b = MakeBatch(data.train, rows, options.sampling, true, data.discrete, rng);
      const double loss = parallel.Backward(b.points.size(0), [&](PolicyNet& replica, int64_t i,
                                                                  int64_t j) {
        return -replica
                    ->LogProb(replica->forward(b.points.slice(0, i, j), b.proprio.slice(0, i, j)),
                              b.actions.slice(0, i, j))
                    .mean();
      });
      optimizer.step();
      total += loss * double(rows.size());
    }
    report.final_train_loss = total / double(order.size());
    const Scores valid = Evaluate(net, held_out, options.sampling, data.discrete);
    curve << epoch << "," << report.final_train_loss << "," << valid.loss << "," << valid.metric
          << "\n"
          << std::flush;
    report.epochs = epoch;
    if (valid.loss < best) {
      best = valid.loss;
      best_scores = valid;
      report.best_epoch = epoch;
      SavePolicy(net, out);
    }
    if (progress) progress->Advance(1, "valid loss " + std::to_string(valid.loss).substr(0, 6));
    if (epoch - report.best_epoch >= options.patience) break;
  }
  report.best_valid_loss = best;
  (data.discrete ? report.valid_accuracy : report.valid_mse) = best_scores.metric;
  report.seconds = core::SecondsSince(start);
  return report;
}

}  // namespace twinforge::learn
