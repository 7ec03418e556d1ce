#include "pipeline/sensing_q_training.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <exception>
#include <fstream>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
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

// The views an episode looks from, one after another: drawn uniformly within the mount's limits.
class EpisodeViews {
 public:
  EpisodeViews(const samrl::OrbitMount& mount, uint64_t seed) : mount_(mount), rng_(seed, 0x5e17) {}
  std::pair<double, double> Next() {
    const double azimuth = rng_.Uniform(mount_.min_azimuth, mount_.max_azimuth);
    return {azimuth, rng_.Uniform(mount_.min_elevation, mount_.max_elevation)};
  }

 private:
  samrl::OrbitMount mount_;
  core::Rng rng_;
};

using NamedPoses = std::vector<std::pair<std::string, core::Pose>>;

// One look of an episode: where it looked from and what the actor believed and planned then, the
// line a worker's looks.<worker>.jsonl holds for it.
struct LookRecord {
  uint64_t seed = 0;  // the episode's
  int look = 0;
  double azimuth = 0, elevation = 0;
  std::array<double, 7> q{};
  double gripper_width = 0;
  NamedPoses objects;
  std::string held;
  int step = 0, steps = 1;
  // What the trial's earlier frames showed in the way (LookContext::occluders): Q is fitted to the
  // view the actor would render with them, as an active look renders it.
  std::vector<samrl::Occluder> occluders;
  // Where the objects stood in the twin when it looked, and where the actor believed them once it
  // had (--return look). Looks written before stop 94 have neither.
  NamedPoses truth, after;
};

nlohmann::json PosesJson(const NamedPoses& poses) {
  nlohmann::json out = nlohmann::json::object();
  for (const auto& [name, p] : poses)
    out[name] = {p.translation.x(), p.translation.y(), p.translation.z(), p.rotation.w(),
                 p.rotation.x(),    p.rotation.y(),    p.rotation.z()};
  return out;
}

NamedPoses PosesFromJson(const nlohmann::json& j) {
  NamedPoses poses;
  for (const auto& [name, v] : j.items()) {
    const auto x = v.get<std::array<double, 7>>();
    core::Pose p;
    p.translation = {x[0], x[1], x[2]};
    p.rotation = core::Quat(x[3], x[4], x[5], x[6]).normalized();
    poses.emplace_back(name, p);
  }
  return poses;
}

nlohmann::json LookJson(const LookRecord& r) {
  nlohmann::json occluders = nlohmann::json::array();
  for (const samrl::Occluder& o : r.occluders)
    occluders.push_back(
        {o.center.x(), o.center.y(), o.center.z(), o.size.x(), o.size.y(), o.size.z()});
  return {{"seed", r.seed},
          {"look", r.look},
          {"azimuth", r.azimuth},
          {"elevation", r.elevation},
          {"q", r.q},
          {"gripper_width", r.gripper_width},
          {"objects", PosesJson(r.objects)},
          {"held", r.held},
          {"step", r.step},
          {"steps", r.steps},
          {"occluders", occluders},
          {"truth", PosesJson(r.truth)},
          {"after", PosesJson(r.after)}};
}

LookRecord LookFromJson(const nlohmann::json& j) {
  LookRecord r;
  r.seed = j.at("seed").get<uint64_t>();
  r.look = j.at("look").get<int>();
  r.azimuth = j.at("azimuth").get<double>();
  r.elevation = j.at("elevation").get<double>();
  r.q = j.at("q").get<std::array<double, 7>>();
  r.gripper_width = j.at("gripper_width").get<double>();
  r.objects = PosesFromJson(j.at("objects"));
  r.held = j.at("held").get<std::string>();
  r.step = j.at("step").get<int>();
  r.steps = j.at("steps").get<int>();
  // Looks written before stop 75 did not record them.
  if (j.contains("occluders"))
    for (const auto& v : j.at("occluders")) {
      const auto x = v.get<std::array<double, 6>>();
      r.occluders.push_back({{x[0], x[1], x[2]}, {x[3], x[4], x[5]}});
    }
  if (j.contains("truth")) r.truth = PosesFromJson(j.at("truth"));
  if (j.contains("after")) r.after = PosesFromJson(j.at("after"));
  return r;
}

// The return Q is fitted to for one episode: its success, or how near the twin came to it.
double EpisodeReturn(const TrialRecord& t, SensingQTrainOptions::Return ret,
                     const std::filesystem::path& dir) {
  if (ret != SensingQTrainOptions::Return::kCloseness) return t.success ? 1.0 : 0.0;
  const auto c = t.grader.is_object() ? t.grader.find("success_closeness") : t.grader.end();
  if (c == t.grader.end() || !c->is_number())
    throw core::ConfigError(dir.string() + ", episode " + std::to_string(t.trial), "grader",
                            "no success_closeness for --return closeness (a run written before "
                            "it was logged: use a fresh directory)");
  return c->get<double>();
}

// A look's own return: the share of the objects not held that the actor believed, once it had
// looked, within `tolerance` (m, in the table's plane) of where they stood.
double LookReturn(const LookRecord& r, double tolerance, const std::filesystem::path& dir) {
  const std::string look =
      dir.string() + ", episode " + std::to_string(r.seed) + ", look " + std::to_string(r.look);
  if (r.truth.empty())
    throw core::ConfigError(look, "truth",
                            "no objects' truth for --return look (a run written before it was "
                            "logged: use a fresh directory)");
  int targets = 0, found = 0;
  for (const auto& [name, truth] : r.truth) {
    if (name == r.held) continue;
    const auto after = std::find_if(r.after.begin(), r.after.end(),
                                    [&name = name](const auto& p) { return p.first == name; });
    if (after == r.after.end())
      throw core::ConfigError(look, "after", "no belief in " + name + " after the look");
    ++targets;
    found += (after->second.translation - truth.translation).head<2>().norm() <= tolerance;
  }
  // Everything held: nothing was to be shown, and nothing missed.
  return targets == 0 ? 1.0 : double(found) / targets;
}

// The looks a worker's file holds, by episode seed and look; a look written twice (an episode
// killed and run again) keeps its last line.
void ReadLooks(const std::filesystem::path& file,
               std::map<std::pair<uint64_t, int>, LookRecord>& looks) {
  std::ifstream in(file);
  std::string line;
  for (int number = 1; std::getline(in, line); ++number) {
    try {
      const LookRecord r = LookFromJson(nlohmann::json::parse(line));
      looks[{r.seed, r.look}] = r;
    } catch (const nlohmann::json::exception& e) {
      throw core::ConfigError(file.string() + ":" + std::to_string(number), "", e.what());
    }
  }
}

// A looks file a killed run left with a torn last line loses that line, so that appending goes on
// after the last whole one.
void DropTornLine(const std::filesystem::path& file) {
  if (!std::filesystem::exists(file)) return;
  std::ifstream in(file, std::ios::binary);
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (text.empty() || text.back() == '\n') return;
  const std::size_t keep =
      text.find_last_of('\n') == std::string::npos ? 0 : text.find_last_of('\n') + 1;
  spdlog::warn("train samrl: {} ends in a torn line (a killed run); dropped", file.string());
  std::filesystem::resize_file(file, keep);
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

// The twin actor, as the harness runs it, with each look's line written once the actor has
// looked: the line then holds where it believed the objects after that look (LookRecord::after).
class LookWriter : public reality::Operator {
 public:
  LookWriter(const std::filesystem::path& file, const std::vector<std::string>& objects)
      : file_(file), objects_(objects), out_(file, std::ios::app) {
    if (!out_) throw core::IoError("train samrl: cannot append to " + file.string());
  }
  void set_actor(samrl::TwinActor* actor) { actor_ = actor; }
  // A look begins: the one before it, if any, is done.
  void Looking(LookRecord r) {
    Flush();
    pending_ = std::move(r);
  }
  reality::OperatorInput Next(const reality::Observation& o) override {
    reality::OperatorInput input = actor_->Next(o);
    Flush();
    return input;
  }
  std::string name() const override { return actor_->name(); }

 private:
  void Flush() {
    if (!pending_) return;
    const auto& estimates = actor_->estimates();
    for (std::size_t i = 0; i < estimates.size() && i < objects_.size(); ++i)
      pending_->after.emplace_back(objects_[i], estimates[i].pose);
    out_ << LookJson(*pending_).dump() << "\n" << std::flush;
    if (!out_) throw core::IoError("train samrl: cannot write to " + file_.string());
    pending_.reset();
  }
  std::filesystem::path file_;
  std::vector<std::string> objects_;
  std::ofstream out_;
  samrl::TwinActor* actor_ = nullptr;
  std::optional<LookRecord> pending_;
};

// How the episodes' actor looks again: as eval's twin actor does when its look chooses the view
// (--look q or active: the held object found in the hand, and an object a later look sees
// believed where that look put it), so that Q learns the views of the actor that will use it.
// Before stop 95 the episodes ran without either, so a later look that saw the block within the
// 5 mm `moved` bound left the belief, and the look's return, as they were.
samrl::RelookOptions EpisodeRelook(const SensingQTrainOptions& options) {
  samrl::RelookOptions relook;
  relook.max_looks = options.max_looks;
  relook.measure_held = relook.refine = true;
  return relook;
}

// One worker: its own simulated twin and twin actor, the trials i % workers == worker. Each look
// is from the episode's next random view, and is appended to `looks_file` once the actor has
// looked.
RealityEvalReport RunEpisodes(const sim::TaskSpec& twin, const SensingQTrainOptions& options,
                              const samrl::OrbitMount& mount, const nlohmann::json& header,
                              int worker, const std::filesystem::path& log,
                              const std::filesystem::path& looks_file,
                              const std::function<void(const TrialRecord&)>& on_trial) {
  const auto robot =
      reality::ProxyReality::SimulatedTwin(twin, reality::ProxyReality::Sensor::kCalibrated);
  const sim::CameraIntrinsics capture =
      samrl::ScaleIntrinsics(sim::MakeCamera(twin.camera).intrinsics, options.capture_scale);
  DropTornLine(looks_file);
  LookWriter writer(looks_file, twin.objects);
  uint64_t episode = 0;
  int looked = 0;
  std::optional<EpisodeViews> views;
  const samrl::Look look = [&](const samrl::LookContext& context) {
    LookRecord r;
    r.seed = episode;
    r.look = looked++;
    std::tie(r.azimuth, r.elevation) = views->Next();
    for (int i = 0; i < 7; ++i) r.q[i] = context.observation.q[i];
    r.gripper_width = context.observation.gripper_width;
    r.objects = context.objects;
    r.held = context.held;
    r.step = context.step;
    r.steps = context.steps;
    r.occluders = context.occluders;
    r.truth = robot->ObjectPoses();
    const core::Pose camera = samrl::OrbitPose(mount, r.azimuth, r.elevation);
    writer.Looking(std::move(r));
    return std::vector<reality::RgbdFrame>{robot->Capture({camera, capture})};
  };
  const samrl::RelookOptions relook = EpisodeRelook(options);
  // The workers share the cores: each fits its objects on one thread.
  samrl::TwinActor actor(std::make_shared<const sim::Task>(twin), *robot, look, true, {}, {},
                         relook, options.workers > 1 ? 1 : 0);
  writer.set_actor(&actor);
  RealityEvalOptions o;
  o.levels = {options.level};
  o.trials = options.episodes;
  o.seed = options.seed;
  o.worker = worker;
  o.workers = options.workers;
  o.on_trial = on_trial;
  o.grader = [&] { return robot->GraderState(); };
  const auto begin = [&](uint64_t seed) {
    episode = seed;
    looked = 0;
    views.emplace(mount, seed);
    actor.Begin(seed);
  };
  return EvaluateOperatorOnReality(*robot, {&writer, begin, header, nullptr}, twin, o, log);
}

}  // namespace

const char* ReturnName(SensingQTrainOptions::Return ret) {
  switch (ret) {
    case SensingQTrainOptions::Return::kSuccess:
      return "success";
    case SensingQTrainOptions::Return::kCloseness:
      return "closeness";
    case SensingQTrainOptions::Return::kLook:
      return "look";
  }
  return "?";
}

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
  const samrl::RelookOptions relook = EpisodeRelook(options);
  const nlohmann::json header = {{"actor", "twin"},
                                 {"look", "a random view on the mount at each look"},
                                 {"max_looks", options.max_looks},
                                 {"look_aside", samrl::RelookOptions{}.look_aside},
                                 {"measure_held", relook.measure_held},
                                 {"refine", relook.refine},
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
        const std::string n = std::to_string(w);
        reports[w] = RunEpisodes(twin, o, mount, header, w, out_dir / ("episodes." + n + ".jsonl"),
                                 out_dir / ("looks." + n + ".jsonl"), on_trial);
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

  // Each look's view as the actor would render it in the twin it believed then, and its plan,
  // paired with the episode's return.
  std::map<std::pair<uint64_t, int>, LookRecord> looks;
  for (int w = 0; w < workers; ++w)
    ReadLooks(out_dir / ("looks." + std::to_string(w) + ".jsonl"), looks);
  real2sim::TwinGeometry geometry(twin, 600);
  const core::PinholeIntrinsics search = samrl::LookSearchCamera();
  const int steps = int(twin.expert.steps.size());
  std::vector<samrl::ViewReturn> samples;
  nlohmann::json views = nlohmann::json::array();
  for (const TrialRecord& t : trials) {
    report.successes += t.success;
    const double episode_return = EpisodeReturn(t, options.ret, out_dir);
    for (auto it = looks.lower_bound({t.seed, 0}); it != looks.end() && it->first.first == t.seed;
         ++it) {
      const LookRecord& r = it->second;
      torch::NoGradGuard no_grad;
      const samrl::TargetView seen = samrl::BelievedView(geometry, r.q, r.gripper_width, r.objects,
                                                         r.held, twin.objects, r.occluders);
      const real2sim::SoftImage image = real2sim::SoftRasterize(
          seen.mesh, search,
          samrl::OrbitPose(mount, torch::tensor({r.azimuth, r.elevation}, torch::kFloat64)));
      const double look_return = options.ret == SensingQTrainOptions::Return::kLook
                                     ? LookReturn(r, options.look_tolerance, out_dir)
                                     : episode_return;
      samples.push_back({samrl::ViewInput(image),
                         options.plan ? samrl::PlanInput(r.step, steps) : torch::Tensor(),
                         look_return, t.trial});
      views.push_back({{"trial", t.trial},
                       {"look", r.look},
                       {"azimuth", r.azimuth},
                       {"elevation", r.elevation},
                       {"step", r.step},
                       {"occluders", r.occluders.size()},
                       {"targets_fill", seen.score(image).item<double>()},
                       {"success", t.success},
                       {"return", look_return}});
    }
  }
  report.episodes = int(trials.size());
  report.looks = int(samples.size());

  torch::manual_seed(options.seed);
  samrl::SensingQNet net(search.height, search.width, options.plan ? steps : 0);
  samrl::SensingQOptions fit = options.fit;
  fit.seed = options.seed;
  report.fit = samrl::FitSensingQ(net, samples, fit);
  core::Rng rng(options.seed, 0xc40);
  const samrl::TargetView at_rest = samrl::TargetVisibilityAtRest(geometry, task, twin.objects);
  report.chosen = samrl::ChooseView(
      at_rest.mesh, search, mount,
      samrl::QScore(net, options.plan ? samrl::PlanInput(0, steps) : torch::Tensor()), rng,
      samrl::LookSearch());
  spdlog::info(
      "train samrl: {}/{} simulated episodes succeeded, {} looks; Q's held-out squared error "
      "{:.3f} (predicting the mean: {:.3f}); its first view: azimuth {:.2f}, elevation {:.2f}, "
      "Q {:.2f}",
      report.successes, report.episodes, report.looks, report.fit.valid_loss,
      report.fit.valid_baseline, report.chosen.azimuth, report.chosen.elevation,
      report.chosen.score);

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
                               {"action", options.plan ? "the expert step the actor does next, "
                                                         "one-hot (PlanInput)"
                                                       : "none: Q reads the view alone"},
                               {"action_dim", net->action_dim()},
                               {"options",
                                {{"episodes", options.episodes},
                                 {"level", options.level},
                                 {"seed", options.seed},
                                 {"capture_scale", options.capture_scale},
                                 {"max_looks", options.max_looks},
                                 {"return", ReturnName(options.ret)},
                                 {"look_tolerance", options.look_tolerance},
                                 {"plan", options.plan},
                                 {"fit_steps", fit.steps}}},
                               {"episodes", report.episodes},
                               {"looks", report.looks},
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
  int action_dim = 0;
  try {
    if (meta.at("twin_hash").get<std::string>() != TwinFingerprint(twin))
      throw core::Error("sensing Q: " + q_file.string() + " was trained on another twin (" +
                        meta.value("twin", std::string("?")) + ") than " + twin.file.string());
    const nlohmann::json& v = meta.at("view");
    model.search = {v.at("width"), v.at("height"), v.at("fx"), v.at("fy"), v.at("cx"), v.at("cy")};
    model.mount = MountFromJson(meta.at("mount"));
    // Qs written before stop 44 read the view alone.
    action_dim = meta.value("action_dim", 0);
  } catch (const nlohmann::json::exception& e) {
    throw core::ConfigError(meta_file.string(), "", e.what());
  }
  const int steps = int(twin.expert.steps.size());
  if (action_dim != 0 && action_dim != steps)
    throw core::ConfigError(meta_file.string(), "action_dim",
                            "a plan of " + std::to_string(action_dim) +
                                " steps; the twin's expert has " + std::to_string(steps));
  model.net = samrl::SensingQNet(model.search.height, model.search.width, action_dim);
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
