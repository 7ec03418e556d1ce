#include "pipeline/sensing_q_training.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <exception>
#include <fstream>
#include <mutex>
#include <nlohmann/json.hpp>
#include <thread>

#include "core/error.h"
#include "core/fs.h"
#include "core/measure.h"
#include "core/rng.h"
#include "pipeline/reality_eval.h"
#include "pipeline/run_directory.h"
#include "real2sim/calibrate/twin_geometry.h"
#include "reality/proxy_reality.h"
#include "samrl/twin_actor.h"
#include "sim/camera.h"

namespace twinforge::pipeline {

namespace {

// The view episode `seed` looks from: drawn uniformly within the mount's limits.
std::pair<double, double> EpisodeView(const samrl::OrbitMount& mount, uint64_t seed) {
  core::Rng rng(seed, 0x5e17);
  const double azimuth = rng.Uniform(mount.min_azimuth, mount.max_azimuth);
  return {azimuth, rng.Uniform(mount.min_elevation, mount.max_elevation)};
}

nlohmann::json MountJson(const samrl::OrbitMount& m) {
  return {{"center", {m.center.x(), m.center.y(), m.center.z()}},
          {"radius", m.radius},
          {"azimuth", {m.min_azimuth, m.max_azimuth}},
          {"elevation", {m.min_elevation, m.max_elevation}}};
}

samrl::OrbitMount MountFromJson(const nlohmann::json& j) {
  samrl::OrbitMount m;
  const auto c = j.at("center").get<std::vector<double>>();
  if (c.size() != 3) throw core::Error("the mount's centre needs 3 coordinates");
  m.center = Eigen::Vector3d(c[0], c[1], c[2]);
  m.radius = j.at("radius").get<double>();
  m.min_azimuth = j.at("azimuth").at(0).get<double>();
  m.max_azimuth = j.at("azimuth").at(1).get<double>();
  m.min_elevation = j.at("elevation").at(0).get<double>();
  m.max_elevation = j.at("elevation").at(1).get<double>();
  return m;
}

// One worker: its own simulated twin and twin actor, the trials i % workers == worker.
RealityEvalReport RunEpisodes(const sim::TaskSpec& twin, const SensingQTrainOptions& options,
                              const samrl::OrbitMount& mount, const nlohmann::json& header,
                              int worker, const std::filesystem::path& log,
                              const std::function<void(const TrialRecord&)>& on_trial) {
  const auto robot = reality::ProxyReality::SimulatedTwin(twin);
  const sim::CameraIntrinsics capture =
      samrl::ScaleIntrinsics(sim::MakeCamera(twin.camera).intrinsics, options.capture_scale);
  core::Pose view;
  const samrl::Look look = [&](const samrl::LookContext&) {
    return std::vector<reality::RgbdFrame>{robot->Capture({view, capture})};
  };
  samrl::RelookOptions once;
  once.max_looks = 1;
  // The workers share the cores: each fits its objects on one thread.
  samrl::TwinActor actor(std::make_shared<const sim::Task>(twin), *robot, look, true, {}, {}, once,
                         options.workers > 1 ? 1 : 0);
  RealityEvalOptions o;
  o.levels = {options.level};
  o.trials = options.episodes;
  o.seed = options.seed;
  o.worker = worker;
  o.workers = options.workers;
  o.on_trial = on_trial;
  const auto begin = [&](uint64_t seed) {
    const auto [azimuth, elevation] = EpisodeView(mount, seed);
    view = samrl::OrbitPose(mount, azimuth, elevation);
    actor.Begin(seed);
  };
  return EvaluateOperatorOnReality(*robot, {&actor, begin, header, nullptr}, twin, o, log);
}

}  // namespace

std::string TwinFingerprint(const sim::TaskSpec& twin) {
  return Fingerprint().AddFile(twin.file).AddFile(twin.file.parent_path() / twin.scene).Hex();
}

SensingQTrainReport TrainSensingQ(const sim::TaskSpec& twin, const SensingQTrainOptions& options,
                                  const std::filesystem::path& out_dir, core::Progress* progress) {
  const auto start = core::Clock::now();
  if (options.episodes < 4 || options.workers < 1)
    throw core::ConfigError("train samrl", "episodes",
                            "at least 4 episodes and one worker, got " +
                                std::to_string(options.episodes) + " and " +
                                std::to_string(options.workers));
  std::filesystem::create_directories(out_dir);
  const sim::Task task(twin);
  const samrl::OrbitMount mount = samrl::ObjectsMount(task);
  const std::string twin_hash = TwinFingerprint(twin);
  const nlohmann::json header = {{"actor", "twin"},
                                 {"look", "a random view on the mount, once"},
                                 {"twin_hash", twin_hash},
                                 {"mount", MountJson(mount)},
                                 {"capture_scale", options.capture_scale}};

  // The episodes, split among the workers.
  std::mutex mutex;
  int finished = 0, successes = 0;
  const auto on_trial = [&](const TrialRecord& r) {
    std::lock_guard<std::mutex> lock(mutex);
    ++finished;
    successes += r.success;
    if (progress)
      progress->Set(finished,
                    "success " + std::to_string(successes) + "/" + std::to_string(finished));
  };
  const int workers = std::min(options.workers, options.episodes);
  std::vector<RealityEvalReport> reports(workers);
  std::vector<std::exception_ptr> errors(workers);
  std::vector<std::thread> threads;
  for (int w = 0; w < workers; ++w)
    threads.emplace_back([&, w] {
      try {
        SensingQTrainOptions o = options;
        o.workers = workers;
        reports[w] = RunEpisodes(twin, o, mount, header, w,
                                 out_dir / ("episodes." + std::to_string(w) + ".jsonl"), on_trial);
      } catch (...) {
        errors[w] = std::current_exception();
      }
    });
  for (auto& t : threads) t.join();
  for (const auto& e : errors)
    if (e) std::rethrow_exception(e);

  SensingQTrainReport report;
  std::vector<TrialRecord> trials;
  for (const auto& r : reports) {
    trials.insert(trials.end(), r.trials.begin(), r.trials.end());
    report.resumed += r.resumed;
  }
  std::sort(trials.begin(), trials.end(),
            [](const TrialRecord& a, const TrialRecord& b) { return a.trial < b.trial; });

  // Each episode's view as the actor would render it in the twin before acting, and its return.
  real2sim::TwinGeometry geometry(twin, 600);
  const samrl::TargetView at_rest = samrl::TargetVisibilityAtRest(geometry, task, twin.objects);
  const core::PinholeIntrinsics search = samrl::LookSearchCamera();
  std::vector<samrl::ViewReturn> samples;
  nlohmann::json views = nlohmann::json::array();
  for (const TrialRecord& t : trials) {
    const auto [azimuth, elevation] = EpisodeView(mount, t.seed);
    torch::NoGradGuard no_grad;
    const real2sim::SoftImage image = real2sim::SoftRasterize(
        at_rest.mesh, search,
        samrl::OrbitPose(mount, torch::tensor({azimuth, elevation}, torch::kFloat64)));
    samples.push_back({samrl::ViewInput(image), torch::Tensor(), t.success ? 1.0 : 0.0});
    views.push_back({{"trial", t.trial},
                     {"azimuth", azimuth},
                     {"elevation", elevation},
                     {"targets_fill", at_rest.score(image).item<double>()},
                     {"success", t.success}});
    report.successes += t.success;
  }
  report.episodes = int(trials.size());

  torch::manual_seed(options.seed);
  samrl::SensingQNet net(search.height, search.width, 0);
  samrl::SensingQOptions fit = options.fit;
  fit.seed = options.seed;
  report.fit = samrl::FitSensingQ(net, samples, fit);
  core::Rng rng(options.seed, 0xc40);
  report.chosen = samrl::ChooseView(at_rest.mesh, search, mount,
                                    samrl::QScore(net, torch::Tensor()), rng, samrl::LookSearch());
  spdlog::info(
      "train samrl: {}/{} simulated episodes succeeded; Q's held-out squared error {:.3f} "
      "(predicting the mean: {:.3f}); its view: azimuth {:.2f}, elevation {:.2f}, Q {:.2f}",
      report.successes, report.episodes, report.fit.valid_loss, report.fit.valid_baseline,
      report.chosen.azimuth, report.chosen.elevation, report.chosen.score);

  report.q_file = out_dir / "q.pt";
  const std::filesystem::path partial = out_dir / "q.pt.partial";
  torch::save(net, partial.string());
  std::filesystem::rename(partial, report.q_file);
  const nlohmann::json meta = {{"twin", twin.name},
                               {"twin_hash", twin_hash},
                               {"q_hash", Fingerprint().AddFile(report.q_file).Hex()},
                               {"view",
                                {{"width", search.width},
                                 {"height", search.height},
                                 {"fx", search.fx},
                                 {"fy", search.fy},
                                 {"cx", search.cx},
                                 {"cy", search.cy}}},
                               {"mount", MountJson(mount)},
                               {"options",
                                {{"episodes", options.episodes},
                                 {"level", options.level},
                                 {"seed", options.seed},
                                 {"capture_scale", options.capture_scale},
                                 {"fit_steps", fit.steps}}},
                               {"episodes", report.episodes},
                               {"successes", report.successes},
                               {"fit",
                                {{"train_mse", report.fit.train_loss},
                                 {"valid_mse", report.fit.valid_loss},
                                 {"valid_mse_of_the_mean", report.fit.valid_baseline}}},
                               {"chosen",
                                {{"azimuth", report.chosen.azimuth},
                                 {"elevation", report.chosen.elevation},
                                 {"q", report.chosen.score}}},
                               {"views", views}};
  core::WriteFileAtomic(out_dir / "q.json", meta.dump(2) + "\n");
  report.seconds = core::SecondsSince(start);
  return report;
}

SensingQModel LoadSensingQ(const std::filesystem::path& q_file, const sim::TaskSpec& twin) {
  std::filesystem::path meta_file = q_file;
  meta_file.replace_extension(".json");
  if (!std::filesystem::is_regular_file(q_file) || !std::filesystem::is_regular_file(meta_file))
    throw core::IoError("sensing Q: " + q_file.string() + " needs " + meta_file.string() +
                        " beside it (train samrl writes both)");
  std::ifstream in(meta_file);
  const nlohmann::json meta = nlohmann::json::parse(in, nullptr, false);
  if (meta.is_discarded() || !meta.is_object())
    throw core::ConfigError(meta_file.string(), "", "not a JSON object");
  SensingQModel model;
  try {
    if (meta.at("twin_hash").get<std::string>() != TwinFingerprint(twin))
      throw core::Error("sensing Q: " + q_file.string() + " was trained on another twin (" +
                        meta.value("twin", std::string("?")) + ") than " + twin.file.string());
    const nlohmann::json& v = meta.at("view");
    model.search = {v.at("width"), v.at("height"), v.at("fx"), v.at("fy"), v.at("cx"), v.at("cy")};
    model.mount = MountFromJson(meta.at("mount"));
  } catch (const nlohmann::json::exception& e) {
    throw core::ConfigError(meta_file.string(), "", e.what());
  }
  model.net = samrl::SensingQNet(model.search.height, model.search.width, 0);
  try {
    torch::load(model.net, q_file.string());
  } catch (const c10::Error& e) {
    throw core::IoError("sensing Q: cannot read " + q_file.string() + ": " +
                        e.what_without_backtrace());
  }
  model.net->eval();
  model.hash = Fingerprint().AddFile(q_file).Hex();
  // q.pt is written first: a run killed before q.json followed leaves the older description.
  if (meta.value("q_hash", std::string()) != model.hash)
    throw core::Error("sensing Q: " + meta_file.string() + " describes another " +
                      q_file.filename().string() +
                      " (a train samrl run stopped between the two?); "
                      "run train samrl again on the same directory to rewrite both");
  return model;
}

}  // namespace twinforge::pipeline
