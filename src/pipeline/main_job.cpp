#include "pipeline/main_job.h"

#include <fstream>
#include <functional>
#include <memory>

#include "core/config.h"
#include "core/error.h"
#include "core/fs.h"
#include "core/log.h"
#include "core/measure.h"
#include "learn/bc.h"
#include "learn/evaluate.h"
#include "learn/ppo.h"
#include "pipeline/reality_eval.h"
#include "pipeline/run_directory.h"
#include "pipeline/twin_sysid.h"
#include "real2sim/build.h"
#include "reality/connect.h"
#include "reality/demos.h"
#include "reality/teleop.h"

namespace twinforge::pipeline {

namespace {

// Writes through `part` and renames to `path` once `write` finished, so a killed stage never
// leaves a file that looks complete.
void WriteThenRename(const std::filesystem::path& path,
                     const std::function<void(const std::filesystem::path&)>& write) {
  std::filesystem::path part = path;
  part += ".part";
  std::filesystem::remove(part);
  write(part);
  std::filesystem::rename(part, path);
}

void WriteJson(const std::filesystem::path& path, const nlohmann::json& value) {
  core::WriteFileAtomic(path, value.dump(2) + "\n");
}

int ReadSuccesses(const std::filesystem::path& report) {
  std::ifstream in(report);
  const nlohmann::json j = nlohmann::json::parse(in, nullptr, false);
  return j.is_object() ? j.value("successes", 0) : 0;
}

class Job {
 public:
  Job(const MainJobOptions& options, const std::filesystem::path& out)
      : o_(options), run_(out), task_(sim::LoadTaskSpec(options.task)) {
    // Every stage works on the run's threads.
    if (o_.distill.threads != learn::DistillOptions{}.threads && o_.distill.threads != o_.threads)
      spdlog::warn(
          "run: distill.threads ({}) is not used; distillation works on the run's threads ({}): "
          "set `threads` (or --threads) instead",
          o_.distill.threads, o_.threads);
  }

  void Run() {
    core::SaveConfig(run_ / "config.json", o_);
    const bool articulated = !task_.joints.empty();
    const std::string reality = Fingerprint().Add(o_.reality).Add(task_.name).Hex();
    std::vector<std::string> scans = {"scan/trajectory.json"};
    if (o_.camera_frames > 0) scans.push_back("camera/frames.json");
    if (articulated) scans.push_back("scan_open/trajectory.json");
    Stage(
        "scan",
        Fingerprint()
            .Add(reality)
            .Add(core::ToJson(o_.scan).dump())
            .Add(std::to_string(o_.camera_frames) + "/" + std::to_string(o_.camera_frames_height) +
                 "/" + std::to_string(o_.camera_frames_spread))
            .Hex(),
        scans, [&] {
          Scan(run_ / "scan", false);
          // The fixed camera sees the scene as it was scanned (before the part is moved).
          if (o_.camera_frames > 0) {
            std::filesystem::remove_all(run_ / "camera");
            reality::Robot& robot = Robot();
            const sim::Kinematics kinematics(
                sim::LoadRobotSpec(reality::RobotDescriptionPath(robot.Info().robot)));
            core::Progress progress("camera frames", o_.camera_frames, "frames");
            reality::CaptureCameraFrames(robot, kinematics,
                                         Eigen::Vector3d(task_.camera.look_at.data()) +
                                             Eigen::Vector3d(0, 0, o_.camera_frames_height),
                                         o_.camera_frames, o_.camera_frames_spread, o_.seed,
                                         run_ / "camera", &progress);
            progress.Finish();
          }
          if (articulated) Scan(run_ / "scan_open", true);
        });
    Stage("twin",
          Fingerprint()
              .AddFile(run_ / "scan/trajectory.json")
              .AddFile(run_ / "scan_open/trajectory.json")
              .Add(core::ToJson(task_).dump())
              .Hex(),
          {"twin/task.yaml", "twin/scene.xml"}, [&] {
            real2sim::BuildOptions b;
            b.task = task_;
            if (articulated) b.scan_after = run_ / "scan_open";
            std::filesystem::remove_all(run_ / "twin");
            WriteJson(run_ / "twin_build.json",
                      real2sim::BuildTwin(run_ / "scan", run_ / "twin", b));
          });
    // Where the fixed camera really is: the twin rendered against its frames.
    std::filesystem::path twin = o_.camera_frames > 0 ? run_ / "calibrated" : run_ / "twin";
    if (o_.camera_frames > 0) {
      std::vector<std::string> calibrated_files = {"calibrated/task.yaml",
                                                   "calibrated/calibration/calibration.json"};
      if (o_.calibrate.mesh.iterations > 0)
        calibrated_files.push_back("calibrated/calibration/mesh.json");
      Stage("calibrate",
            Fingerprint()
                .AddFile(run_ / "twin/task.yaml")
                .AddFile(run_ / "twin/scene.xml")
                .AddFile(run_ / "camera/frames.json")
                .AddFile(run_ / "scan/frames.json")
                .Add(core::ToJson(o_.calibrate).dump())
                .Hex(),
            calibrated_files, [&] {
              const core::Scan frames = core::ReadScan(run_ / "camera");
              core::Progress progress("calibrate", o_.calibrate.ProgressSteps(), "steps");
              const auto c =
                  real2sim::CalibrateCamera(sim::LoadTaskSpec((run_ / "twin/task.yaml").string()),
                                            frames, o_.calibrate, &progress);
              progress.Finish();
              std::filesystem::remove_all(run_ / "calibrated");
              real2sim::WriteCalibratedTwin(run_ / "twin", frames, c, o_.calibrate,
                                            run_ / "calibrated");
              // The scanned meshes against the scan's own frames, each frame's pose corrected.
              if (o_.calibrate.mesh.iterations > 0) {
                core::Progress mesh_progress("refine meshes", o_.calibrate.mesh.iterations,
                                             "steps");
                real2sim::RefineTwinMeshes(run_ / "calibrated", core::ReadScan(run_ / "scan"),
                                           o_.calibrate.mesh, &mesh_progress);
                mesh_progress.Finish();
              }
            });
      // Real frames become clouds with the calibrated camera, in the demos and the evaluations.
      task_.camera = sim::LoadTaskSpec((twin / "task.yaml").string()).camera;
    }
    // How the real arm and the moving parts respond: the twin's servo is ideal and its scene
    // values are the recipe's guesses until sysid measures them.
    if (o_.sysid) {
      const std::filesystem::path identified = run_ / "identified";
      Stage("sysid",
            Fingerprint()
                .Add(reality)
                .AddFile(twin / "task.yaml")
                .AddFile(twin / "scene.xml")
                .Add(core::ToJson(o_.sysid_options).dump())
                .Hex(),
            {"identified/task.yaml", "identified/sysid/sysid.json"}, [&] {
              std::filesystem::remove_all(identified);
              core::Progress progress("sysid", 0, "replays");
              real2sim::RobotSysidOptions sysid = o_.sysid_options;
              sysid.threads = o_.threads;
              IdentifyTwin(Robot(), twin, identified, sysid, &progress);
              progress.Finish();
            });
      twin = identified;
    }
    const std::string camera = core::ToJson(task_.camera).dump();
    Stage("demos", Fingerprint().Add(reality).Add(camera).Add(std::to_string(o_.demos)).Hex(),
          {"demos/real.hdf5"}, [&] {
            reality::Robot& robot = Robot();
            const auto op = reality::MakeOperator(robot, "auto", task_);
            reality::RecordOptions r;
            r.demos = o_.demos;
            r.seed = o_.seed;
            std::filesystem::create_directories(run_ / "demos");
            core::Progress progress("demos", o_.demos, "demos");
            WriteThenRename(run_ / "demos/real.hdf5", [&](const std::filesystem::path& part) {
              const auto report = reality::RecordDemos(robot, *op, task_, r, part, &progress);
              if (report.kept < o_.demos)
                throw core::Error("demos: only " + std::to_string(report.kept) + " of " +
                                  std::to_string(o_.demos) + " demos in " +
                                  std::to_string(report.attempts) + " attempts");
            });
            progress.Finish();
          });
    Stage("bc",
          Fingerprint()
              .AddFile(run_ / "demos/real.hdf5")
              .Add(std::to_string(o_.seed) + "/" + std::to_string(o_.bc_epochs))
              .Hex(),
          {"policies/bc_real.pt"}, [&] {
            learn::BcOptions b;
            b.seed = o_.seed;
            b.max_epochs = o_.bc_epochs;
            b.threads = o_.threads;
            core::Progress progress("bc", b.max_epochs, "epochs");
            const auto r = learn::TrainBc(run_ / "demos/real.hdf5", run_ / "policies/bc_real.pt", b,
                                          &progress);
            progress.Finish();
            WriteJson(run_ / "policies/bc_real.json", {{"valid_accuracy", r.valid_accuracy},
                                                       {"epochs", r.epochs},
                                                       {"seconds", r.seconds}});
          });
    auto twin_task =
        std::make_shared<const sim::Task>(sim::LoadTaskSpec((twin / "task.yaml").string()));
    const bool discrete = twin_task->spec().control.action == sim::ActionMode::kDiscrete;
    const std::string twin_hash =
        Fingerprint().AddFile(twin / "task.yaml").AddFile(twin / "scene.xml").Hex();
    Stage(
        "inverse_distill",
        Fingerprint()
            .Add(twin_hash)
            .AddFile(run_ / "policies/bc_real.pt")
            .Add(std::to_string(o_.inverse_demos) + "/" + std::to_string(o_.inverse_attempts) +
                 "/" + std::to_string(o_.inverse_temperature) + "/" + o_.sim_demos)
            .Hex(),
        {"demos/sim.hdf5"}, [&] {
          learn::InverseDistillOptions i;
          i.successes = o_.inverse_demos;
          i.rollout.episodes = o_.inverse_attempts;
          i.rollout.sample = true;
          i.rollout.temperature = o_.inverse_temperature;
          i.rollout.threads = o_.threads;
          i.rollout.seed = o_.seed;
          const bool expert = o_.sim_demos == "expert";
          core::Progress progress(expert ? "sim demos (scripted operator)" : "inverse distillation",
                                  o_.inverse_demos, "demos");
          learn::InverseDistillReport r;
          WriteThenRename(run_ / "demos/sim.hdf5", [&](const std::filesystem::path& part) {
            if (expert) {
              r = learn::ExpertDemos(twin_task, i, part, &progress);
              return;
            }
            r = learn::InverseDistill(run_ / "policies/bc_real.pt", twin_task, i, part, &progress);
            if (r.successes == 0)
              spdlog::warn(
                  "inverse distillation: the real-demo policy succeeded in none of {} episodes in "
                  "the twin; the teacher trains by PPO alone, which rarely learns a sparse task "
                  "(record more demos, raise inverse_attempts, or take the sim demos from the "
                  "twin's scripted operator: --sim-demos expert)",
                  r.attempts);
          });
          progress.Finish();
          WriteJson(run_ / "demos/sim.json", {{"source", o_.sim_demos},
                                              {"attempts", r.attempts},
                                              {"successes", r.successes},
                                              {"success_rate", r.success_rate()},
                                              {"seconds", r.seconds}});
        });
    // The teacher trains, and is distilled, in the twin with its physics randomized: as its task
    // file says if it says, else as the run's `physics` says (tasks are data).
    const std::string physics = core::ToJson(o_.physics).dump();
    auto train_task = twin_task;
    if (o_.physics.enabled() && !twin_task->spec().randomization.physics.enabled()) {
      sim::TaskSpec spec = twin_task->spec();
      spec.randomization.physics = o_.physics;
      train_task = std::make_shared<const sim::Task>(spec);
    }
    Stage("rl",
          Fingerprint()
              .Add(twin_hash)
              .Add(physics)
              .AddFile(run_ / "demos/sim.hdf5")
              .Add(std::to_string(o_.rl_envs) + "/" + std::to_string(o_.seed) + "/" +
                   std::to_string(o_.rl_bc_coef))
              .Add(std::to_string(o_.rl_minutes) + "/" + std::to_string(o_.rl_target) + "/" +
                   std::to_string(o_.rl_iterations))
              .Add(std::to_string(o_.rl_bc_pretrain_steps) + "/" +
                   std::to_string(o_.rl_critic_warmup))
              .Hex(),
          {"policies/teacher.pt", "policies/teacher.curve.svg"}, [&] {
            learn::PpoOptions p;
            p.num_envs = o_.rl_envs;
            p.threads = o_.threads;
            p.seed = o_.seed;
            p.max_iterations = o_.rl_iterations;
            p.max_seconds = 60 * o_.rl_minutes;
            p.target_success = o_.rl_target;
            p.bc_coef = o_.rl_bc_coef;
            p.eval_episodes = o_.rl_eval_episodes;
            // A continuous teacher is judged on its mean action. Its noise is one standard
            // deviation per component for every state: fitted to the operator's demos it is ten
            // times what a 1.5 mm insertion allows (peg: 29-49% greedy, 0% sampled).
            p.eval_sample = discrete;
            p.bc_pretrain_steps = o_.rl_bc_pretrain_steps;
            p.critic_warmup = o_.rl_critic_warmup;
            core::Progress progress("rl", o_.rl_iterations, "iterations");
            const bool demos = ReadSuccesses(run_ / "demos/sim.json") > 0;
            // A checkpoint left by a killed run (or a smaller budget) resumes; one made from
            // other inputs (new sim demos, a rebuilt twin) is set aside and the teacher starts
            // over.
            const auto r = learn::TrainPpo(train_task, demos ? run_ / "demos/sim.hdf5" : "",
                                           run_ / "policies/teacher.pt", p,
                                           learn::CheckpointMode::kResumeOrStartOver, &progress);
            progress.Finish();
            if (r.stopped_by == "seconds")
              spdlog::warn(
                  "rl: the teacher stopped at rl_minutes ({}) after {} iterations{}: it, and "
                  "everything after it, depends on this machine's speed, so the same seed "
                  "elsewhere may give another student; for a run any machine repeats, give "
                  "rl_iterations and set rl_minutes to 0",
                  o_.rl_minutes, r.iterations,
                  o_.rl_iterations > 0 ? " of rl_iterations " + std::to_string(o_.rl_iterations)
                                       : std::string());
            WriteJson(run_ / "policies/teacher.json",
                      {{"best_eval_success", r.best_eval_success},
                       {"iterations", r.iterations},
                       {"env_steps", r.env_steps},
                       {"stopped_by", r.stopped_by},
                       {"seconds", r.seconds},
                       {"update_samples_per_s", r.update_samples_per_s},
                       {"update_share_of_matmul_peak", r.update_share_of_matmul_peak}});
          });
    Fingerprint distill_inputs;
    distill_inputs.Add(twin_hash)
        .Add(physics)
        .AddFile(run_ / "policies/teacher.pt")
        .AddFile(run_ / "demos/real.hdf5")
        .Add(DistillFingerprintOptions(o_));
    if (!o_.co_train) distill_inputs.Add("sim only");  // co-trained runs keep their fingerprint
    Stage("distill", distill_inputs.Hex(), {"policies/student.pt"}, [&] {
      learn::DistillOptions d = o_.distill;
      d.threads = o_.threads;
      if (!discrete) d.teacher_sample = d.student_sample = false;  // mean actions, as above
      core::Progress progress("distill", 3 + d.dagger_rounds, "stages");
      learn::TrainDistill(run_ / "policies/teacher.pt", train_task,
                          o_.co_train ? run_ / "demos/real.hdf5" : "", run_ / "policies/student.pt",
                          d, &progress);
      progress.Finish();
    });
    for (const std::string policy : {"student", "bc_real"}) {
      RealityEvalOptions e;
      e.levels = o_.levels;
      e.trials = o_.trials;
      e.seed = o_.seed + 5000;
      e.frames = run_ / "eval/frames" / policy;
      // A discrete policy acts as distillation chose it, by its sampled success in the twin.
      // Measured on the proxy drawer (student, 50 trials per level): sampled 62 / 42 / 46 %
      // against greedy 46 / 36 / 32 % (stop 27), and 46 / 16 / 34 % against 38 / 14 / 30 %
      // (stop 26).
      e.sample = discrete && o_.distill.student_sample;
      // A new policy or protocol starts a new trial log; the old one is kept beside it.
      e.set_aside_other_logs = true;
      const std::filesystem::path file = run_ / ("policies/" + policy + ".pt");
      Stage("eval_" + policy,
            Fingerprint()
                .Add(reality)
                .Add(camera)
                .AddFile(file)
                .Add(std::to_string(e.trials) + "/" + std::to_string(e.seed) +
                     (e.sample ? "/sampled" : "/greedy"))
                .Add(core::ToJson(o_.levels).dump())
                .Hex(),
            {"eval/" + policy + ".json"}, [&] {
              const std::filesystem::path log = run_ / ("eval/" + policy + ".jsonl");
              core::Progress progress("eval " + policy, int64_t(e.levels.size()) * e.trials,
                                      "trials");
              const auto r = EvaluateOnReality(Robot(), file, task_, e, log, nullptr, &progress);
              progress.Finish();
              nlohmann::json j = ToJson(r);
              j["sample"] = e.sample;
              WriteJson(run_ / ("eval/" + policy + ".json"), j);
            });
    }
    // The report reads whatever the run holds now: it is written every time. (A fingerprint of
    // the clock made it "up to date" when two runs ended within the same second.)
    Stage(
        "report", "", {"eval/report.html"}, [&] { WriteReport(run_.root()); }, Rerun::kAlways);
    spdlog::info("run: done in {:.0f} min; report {}", TotalMinutes(),
                 (run_ / "eval/report.html").string());
  }

 private:
  enum class Rerun { kWhenInputsChange, kAlways };

  void Stage(const std::string& name, const std::string& inputs,
             const std::vector<std::string>& outputs, const std::function<void()>& body,
             Rerun rerun = Rerun::kWhenInputsChange) {
    ++index_;
    if (rerun == Rerun::kWhenInputsChange && run_.UpToDate(name, inputs)) {
      spdlog::info("run: stage {}/{} {}: up to date", index_, stages_, name);
      return;
    }
    spdlog::info("run: stage {}/{} {} ({:.1f} min into this session)", index_, stages_, name,
                 TotalMinutes());
    const auto start = core::Clock::now();
    try {
      body();
    } catch (const core::Error& e) {
      throw core::Error("run " + run_.root().string() + ": stage '" + name +
                        "' failed: " + e.what());
    }
    run_.Record(name, {inputs, outputs, core::SecondsSince(start), ""});
  }

  // Minutes since this session of the run started.
  double TotalMinutes() const { return core::SecondsSince(start_) / 60; }

  void Scan(const std::filesystem::path& dir, bool operate_first) {
    reality::Robot& robot = Robot();
    if (operate_first) {
      const auto op = reality::MakeOperator(robot, "auto", task_);
      spdlog::info("scan: the {} changes the scene first", op->name());
      reality::OperateThenHome(robot, *op, task_);
    }
    std::filesystem::remove_all(dir);
    const auto path = reality::ScanPath(task_, o_.scan);
    core::Progress progress("scan", static_cast<int64_t>(path.size()), "frames");
    reality::CaptureScan(robot, path, reality::ScanIntrinsics(o_.scan), dir, &progress);
    progress.Finish();
  }

  // One connection for every stage that needs reality, opened when first needed.
  reality::Robot& Robot() {
    if (!connection_) {
      if (o_.reality.empty())
        throw core::ConfigError("run", "reality", "an address (tcp://host:port or proxy:WORLD)");
      connection_ = std::make_unique<reality::RealityConnection>(
          reality::ConnectOptions{.address = o_.reality, .token = o_.token});
    }
    return connection_->robot();
  }

  MainJobOptions o_;
  int stages_ = 10 + (o_.camera_frames > 0) + o_.sysid;
  RunDirectory run_;
  sim::TaskSpec task_;
  std::unique_ptr<reality::RealityConnection> connection_;
  int index_ = 0;
  core::Clock::time_point start_ = core::Clock::now();
};

}  // namespace

std::string DistillFingerprintOptions(const MainJobOptions& options) {
  core::Json distill = core::ToJson(options.distill);
  // Threads do not change the student (it is the same on any number, and a run uses its own
  // `threads`), so distill.threads is hashed at its default: setting it redoes nothing, and a
  // run that never set it hashes what it always did.
  distill["threads"] = learn::DistillOptions{}.threads;
  // Runs made before the student's point count was an option (stop 70) keep their fingerprint
  // at the default count, so updating does not redo their distillation.
  if (options.distill.sampling.n == learn::PointSampling{}.n) distill.erase("points");
  return distill.dump();
}

void RunMainJob(const MainJobOptions& options, const std::filesystem::path& out) {
  Job(options, out).Run();
}

}  // namespace twinforge::pipeline
