#include "app/train_commands.h"

#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>

#include "app/sim_commands.h"
#include "core/error.h"
#include "core/log.h"
#include "learn/bc.h"
#include "learn/bench.h"
#include "learn/distill.h"
#include "learn/evaluate.h"
#include "learn/imitate.h"
#include "learn/ppo.h"
#include "learn/rollout.h"
#include "sim/task.h"

namespace twinforge::app {
namespace {

// The point counts a policy may be given (`--points` of bc, distill and bench).
const CLI::Range kPointCountRange(learn::PointSampling::kMinN, learn::PointSampling::kMaxN);

struct BcCli {
  std::string demos, out;
  learn::BcOptions options;
};

// The task to train on: `task` (a name or a task.yaml), or the twin's in `twin` (its task must
// be `task`). With `controller`, a task.yaml `sysid` wrote, the arm follows its commands through
// the controller identified there (control.servo, control.arm_scales, control.grip_force), not
// the task's own.
std::shared_ptr<const sim::Task> LoadTrainTask(const std::string& task, const std::string& twin,
                                               const std::string& controller = "") {
  sim::TaskSpec spec;
  if (twin.empty()) {
    spec = sim::LoadTaskSpec(task);
  } else {
    const std::filesystem::path file = std::filesystem::path(twin) / "task.yaml";
    if (!std::filesystem::exists(file))
      throw core::IoError(twin + ": no task.yaml (make the twin with `twin build --task " + task +
                          "`)");
    spec = sim::LoadTaskSpec(file.string());
    if (!task.empty() && spec.name != task)
      throw core::ConfigError(file.string(), "name",
                              "the twin is of task '" + spec.name + "', not '" + task + "'");
  }
  if (!controller.empty()) {
    const sim::TaskSpec identified = sim::LoadTaskSpec(controller);
    if (identified.control.servo.ideal())
      throw core::ConfigError(controller, "control.servo",
                              "an ideal servo: not a controller sysid identified");
    spec.control.servo = identified.control.servo;
    spec.control.arm_scales = identified.control.arm_scales;
    spec.control.grip_force = identified.control.grip_force;
  }
  return std::make_shared<const sim::Task>(std::move(spec));
}

// --controller, for the stages that train in the twin: see LoadTrainTask.
void AddControllerOption(CLI::App& c, std::string& controller) {
  c.add_option("--controller", controller,
               "a task.yaml sysid wrote (`sysid --out DIR`: DIR/task.yaml): the twin's arm "
               "follows its commands through the controller identified there (latency, servo "
               "interpolation, gains), as the real arm does")
      ->check(CLI::ExistingFile);
}

struct InverseDistillCli {
  std::string policy, task, twin, controller, out;
  learn::InverseDistillOptions options;
};

struct RlCli {
  std::string task, twin, controller, demos, out;
  bool fresh = false;
  learn::PpoOptions options;
};

struct DistillCli {
  std::string teacher, task, twin, real, out;
  learn::DistillOptions options;
};

struct ExportCli {
  std::string policy, out;
};

void AddInverseDistill(CLI::App& train, int& exit_code) {
  auto cli = std::make_shared<InverseDistillCli>();
  cli->options.rollout.sample = true;
  cli->options.rollout.episodes = 300;
  cli->options.rollout.threads = 2;
  auto* c = train.add_subcommand(
      "inverse-distill",
      "roll a real-demo policy out in the twin; keep its successes as sim demos (JSON report)");
  c->add_option("--policy", cli->policy,
                "policy from `train bc`, or `expert`: the twin's scripted operator (a person "
                "demonstrating in the twin) for tasks whose real-demo policy never succeeds there")
      ->required();
  c->add_option("--task", cli->task, "task name (the twin's) or task.yaml")->required();
  c->add_option("--twin", cli->twin,
                "twin directory (`twin build --out`); default: the task's "
                "own scene");
  AddControllerOption(*c, cli->controller);
  c->add_option("--n", cli->options.successes, "successful episodes to keep")
      ->check(CLI::PositiveNumber);
  c->add_option("--max-episodes", cli->options.rollout.episodes, "budget of attempts")
      ->check(CLI::PositiveNumber);
  c->add_option("--level", cli->options.rollout.level, "randomization level 0..3")
      ->check(CLI::Range(0, 3));
  c->add_option("--temperature", cli->options.rollout.temperature,
                "sampling temperature of the policy's moves (noise)")
      ->check(CLI::Range(0.05, 10.0));
  c->add_flag("!--greedy", cli->options.rollout.sample, "take the most likely move, no noise");
  c->add_option("--seed", cli->options.rollout.seed, "seed");
  c->add_option("--threads", cli->options.rollout.threads, "worker threads")
      ->check(CLI::PositiveNumber);
  c->add_option("--out", cli->out, "sim demos HDF5 to write (must not exist)")->required();
  c->callback([cli, &exit_code] {
    auto task = LoadTrainTask(cli->task, cli->twin, cli->controller);
    core::Progress progress("inverse distillation", cli->options.successes, "demos");
    const learn::InverseDistillReport r =
        cli->policy == "expert"
            ? learn::ExpertDemos(task, cli->options, cli->out, &progress)
            : learn::InverseDistill(cli->policy, task, cli->options, cli->out, &progress);
    progress.Finish();
    const nlohmann::json report = {{"policy", cli->policy},
                                   {"task", task->spec().name},
                                   {"scene", task->spec().scene},
                                   {"out", cli->out},
                                   {"attempts", r.attempts},
                                   {"successes", r.successes},
                                   {"success_rate", r.success_rate()},
                                   {"seconds", r.seconds}};
    std::cout << report.dump(2) << "\n";
    exit_code = r.successes >= cli->options.successes ? 0 : 3;
    if (exit_code)
      spdlog::error("inverse distillation: only {} of {} demos within {} attempts", r.successes,
                    cli->options.successes, r.attempts);
  });
}

void AddDistill(CLI::App& train, int& exit_code) {
  auto cli = std::make_shared<DistillCli>();
  auto* c = train.add_subcommand(
      "distill",
      "teacher-student distillation into a point-cloud policy, co-trained with real demos (JSON)");
  c->add_option("--teacher", cli->teacher, "state teacher from `train rl`")
      ->required()
      ->check(CLI::ExistingFile);
  c->add_option("--task", cli->task, "task name (the twin's) or task.yaml")->required();
  c->add_option("--twin", cli->twin, "twin directory; default: the task's own scene");
  c->add_option("--real-demos", cli->real, "real demos to co-train with, or none")->required();
  c->add_option("--out", cli->out, "student policy; its per-stage curve goes beside it (.csv)")
      ->required();
  auto& o = cli->options;
  c->add_option("--synthetic", o.synthetic_episodes,
                "stage 1: teacher episodes on synthetic clouds");
  c->add_option("--rendered", o.rendered_episodes, "stage 2: teacher episodes on rendered depth");
  c->add_option("--distractors", o.distractor_episodes,
                "stage 3: teacher episodes with distractors (level 2)");
  c->add_option("--dagger-rounds", o.dagger_rounds, "stage 4: DAgger rounds");
  c->add_option("--dagger-episodes", o.dagger_episodes, "student episodes per DAgger round");
  c->add_option("--train-steps", o.train_steps, "gradient steps after each stage and round")
      ->check(CLI::PositiveNumber);
  c->add_option("--eval-episodes", o.eval_episodes,
                "episodes scoring the last stage's student in the twin (earlier students are "
                "scored on the next DAgger round's episodes; the best is kept; 0: no scoring, "
                "keep the last)");
  c->add_option("--real-weight", o.real_weight,
                "the real demos' share of each batch relative to each sim source's (1: equal)")
      ->check(CLI::Range(1e-3, 1e3));
  c->add_option("--lr", o.learning_rate, "AdamW learning rate")->check(CLI::Range(1e-6, 1.0));
  c->add_option("--points", o.sampling.n, "points the student sees")->check(kPointCountRange);
  c->add_option("--level", o.level, "randomization level 0..3")->check(CLI::Range(0, 3));
  c->add_option("--seed", o.seed, "seed");
  c->add_option("--threads", o.threads, "worker threads")->check(CLI::PositiveNumber);
  c->callback([cli, &exit_code] {
    auto task = LoadTrainTask(cli->task, cli->twin);
    const std::string real = cli->real == "none" ? "" : cli->real;
    if (!real.empty() && !std::filesystem::exists(real))
      throw core::IoError("--real-demos " + real + ": no such file (or say none)");
    const auto& o = cli->options;
    core::Progress progress("distill", 3 + o.dagger_rounds, "stages");
    const learn::DistillReport r =
        learn::TrainDistill(cli->teacher, task, real, cli->out, o, &progress);
    progress.Finish();
    nlohmann::json stages = nlohmann::json::array();
    for (const auto& s : r.stages)
      stages.push_back({{"stage", s.name},
                        {"episodes", s.episodes},
                        {"successes", s.successes},
                        {"kept", s.kept},
                        {"steps", s.steps},
                        {"loss", s.loss},
                        {"student_success", s.student},
                        {"seconds", s.seconds}});
    const nlohmann::json report = {{"teacher", cli->teacher},    {"task", task->spec().name},
                                   {"student", cli->out},        {"real_demos", real},
                                   {"real_steps", r.real_steps}, {"stages", stages},
                                   {"curve", r.curve.string()},  {"seconds", r.seconds}};
    std::cout << report.dump(2) << "\n";
    exit_code = 0;
  });
}

void AddRl(CLI::App& train, int& exit_code) {
  auto cli = std::make_shared<RlCli>();
  auto* c = train.add_subcommand(
      "rl", "PPO + BC on privileged state in the twin; resumes its checkpoint (JSON report)");
  c->add_option("--task", cli->task, "task name (the twin's) or task.yaml")->required();
  c->add_option("--twin", cli->twin, "twin directory; default: the task's own scene");
  c->add_option("--demos", cli->demos, "sim demos from `train inverse-distill`, or none")
      ->required();
  c->add_option("--out", cli->out,
                "teacher policy; curve (.curve.csv/.svg) and checkpoint "
                "(.ckpt) beside it")
      ->required();
  auto& o = cli->options;
  c->add_option("--envs", o.num_envs, "parallel environments")->check(CLI::PositiveNumber);
  c->add_option("--threads", o.threads, "worker threads")->check(CLI::PositiveNumber);
  c->add_option("--level", o.level, "randomization level 0..3")->check(CLI::Range(0, 3));
  c->add_option("--seed", o.seed, "seed");
  c->add_option("--bc-coef", o.bc_coef, "weight of the BC loss")->check(CLI::Range(0.0, 100.0));
  c->add_option("--bc-pretrain-steps", o.bc_pretrain_steps,
                "Adam steps of BC alone on the demos before PPO (0: none)")
      ->check(CLI::NonNegativeNumber);
  c->add_option("--critic-warmup", o.critic_warmup,
                "first iterations that train the value network alone")
      ->check(CLI::NonNegativeNumber);
  c->add_option("--init", o.init_policy,
                "start from this state policy (train imitate's actor) instead of BC pretraining; "
                "its observation normalization is kept")
      ->check(CLI::ExistingFile);
  c->add_option("--init-std", o.init_std,
                "with --init: the actions' starting standard deviation, in units of the per-step "
                "limits")
      ->check(CLI::Range(1e-4, 1.0));
  AddControllerOption(*c, cli->controller);
  c->add_option("--lr", o.learning_rate, "Adam learning rate")->check(CLI::Range(1e-6, 1.0));
  c->add_option("--target", o.target_success, "stop at this evaluation success rate")
      ->check(CLI::Range(0.0, 1.0));
  c->add_flag("!--greedy-eval", o.eval_sample,
              "evaluate the mean or most likely action (default: sampled, as PPO trains)");
  c->add_option("--eval-every", o.eval_every, "iterations between evaluations")
      ->check(CLI::PositiveNumber);
  c->add_option("--eval-episodes", o.eval_episodes, "episodes per evaluation")
      ->check(CLI::PositiveNumber);
  c->add_option("--minutes", o.max_seconds,
                "wall-clock budget in minutes (0: none); the run then depends on the machine's "
                "speed")
      ->transform([](std::string v) { return std::to_string(std::stod(v) * 60); });
  c->add_option("--max-steps", o.max_env_steps, "env-step budget (0: none)");
  c->add_option("--iterations", o.max_iterations,
                "iteration budget (0: none); default 200, unless --minutes or --max-steps is "
                "given alone");
  c->add_flag("--fresh", cli->fresh, "discard an existing checkpoint");
  c->callback([cli, c, &exit_code] {
    // A budget asked for alone is the budget, not a cap under the default iteration count.
    if ((c->count("--minutes") || c->count("--max-steps")) && !c->count("--iterations"))
      cli->options.max_iterations = 0;
    auto task = LoadTrainTask(cli->task, cli->twin, cli->controller);
    const std::string demos = cli->demos == "none" ? "" : cli->demos;
    if (!demos.empty() && !std::filesystem::exists(demos))
      throw core::IoError("--demos: no file " + demos + " (use --demos none for PPO from scratch)");
    core::Progress progress("rl", cli->options.max_iterations, "iterations");
    const learn::PpoReport r = learn::TrainPpo(
        task, demos, cli->out, cli->options,
        cli->fresh ? learn::CheckpointMode::kStartOver : learn::CheckpointMode::kResume, &progress);
    progress.Finish();
    const nlohmann::json report = {
        {"policy", cli->out},
        {"task", task->spec().name},
        {"demos", demos.empty() ? "none" : demos},
        {"iterations", r.iterations},
        {"resumed_from", r.resumed_from},
        {"env_steps", r.env_steps},
        {"seconds", r.seconds},
        {"stopped_by", r.stopped_by},
        {"best_eval_success", r.best_eval_success},
        {"best_iteration", r.best_iteration},
        {"pretrain_bc_loss", r.pretrain_bc_loss},  // NaN is written as null
        {"pretrain_eval_success", r.pretrain_eval_success},
        {"update_samples_per_s", r.update_samples_per_s},
        {"matmul_peak_gflops", r.matmul_peak_gflops},
        {"update_share_of_matmul_peak", r.update_share_of_matmul_peak},
        {"curve_csv", r.curve_csv.string()},
        {"curve_svg", r.curve_svg.string()},
        {"checkpoint", r.checkpoint.string()}};
    std::cout << report.dump(2) << "\n";
    exit_code = 0;
  });
}

void AddExport(CLI::App& train, int& exit_code) {
  auto cli = std::make_shared<ExportCli>();
  auto* c = train.add_subcommand(
      "export", "write a policy as TorchScript for Python: torch.jit.load(path)(points, proprio)");
  c->add_option("--policy", cli->policy, "policy file")->required();
  c->add_option("--out", cli->out, "TorchScript file to write")->required();
  c->callback([cli, &exit_code] {
    learn::PolicyNet net = learn::LoadPolicy(cli->policy);
    learn::ExportTorchScript(net, cli->out);
    std::cout << nlohmann::json({{"policy", cli->policy}, {"torchscript", cli->out}}).dump(2)
              << "\n";
    exit_code = 0;
  });
}

// `train imitate`: SAM-RL's actor, a state policy taught on the twin's scripted expert's episodes
// with noise injected into its actions.
void AddImitate(CLI::App& train, int& exit_code) {
  struct Cli {
    std::string task, twin, controller, out;
    learn::ImitationOptions options;
  };
  auto cli = std::make_shared<Cli>();
  auto* c = train.add_subcommand(
      "imitate",
      "SAM-RL's actor by imitation in the twin: a state policy taught on the twin's scripted "
      "expert's episodes, noise injected into its actions (DART); the twin actor acts with it "
      "(eval --actor twin --actor-policy FILE) (JSON report)");
  auto& o = cli->options;
  c->add_option("--task", cli->task, "task name (the twin's) or task.yaml")->required();
  c->add_option("--twin", cli->twin,
                "twin directory (`twin build --out`); default: the task's own");
  AddControllerOption(*c, cli->controller);
  c->add_option("--out", cli->out, "policy file to write; its curve goes beside it (.curve.csv)")
      ->required();
  c->add_option("--rounds", o.rounds, "rounds: episodes, then training and evaluation")
      ->check(CLI::Range(1, 1000));
  c->add_option("--episodes", o.episodes, "expert episodes per round")->check(CLI::PositiveNumber);
  c->add_option("--train-steps", o.train_steps, "Adam steps after each round")
      ->check(CLI::PositiveNumber);
  c->add_option("--lr", o.learning_rate, "Adam learning rate")->check(CLI::Range(1e-6, 1.0));
  c->add_option("--noise", o.noise,
                "noise on the expert's actions (its labels stay clean): Gaussian, in units of the "
                "per-step limits (discrete: the chance of a random move)")
      ->check(CLI::Range(0.0, 10.0));
  AddOptimizeMovesOption(*c, o.plan);
  c->add_option("--level", o.level, "randomization level 0..3")->check(CLI::Range(0, 3));
  c->add_option("--eval-episodes", o.eval_episodes,
                "episodes evaluating the learner after each round (0: none, keep the last)")
      ->check(CLI::NonNegativeNumber);
  c->add_option("--seed", o.seed, "seed");
  c->add_option("--threads", o.threads, "worker threads (the result does not depend on them)")
      ->check(CLI::PositiveNumber);
  c->callback([cli, &exit_code] {
    auto task = LoadTrainTask(cli->task, cli->twin, cli->controller);
    core::Progress progress("imitate", int64_t(cli->options.rounds) * cli->options.episodes,
                            "expert episodes");
    const learn::ImitationReport r = learn::TrainImitation(task, cli->out, cli->options, &progress);
    progress.Finish();
    nlohmann::json rounds = nlohmann::json::array();
    for (const auto& row : r.rounds)
      rounds.push_back({{"round", row.round},
                        {"episodes", row.episodes},
                        {"successes", row.successes},
                        {"planned_moves", row.plans.planned_moves},
                        {"failed_plans", row.plans.failed_plans},
                        {"steps", row.steps},
                        {"loss", row.loss},
                        {"learner_success", row.learner}});
    std::cout << nlohmann::json{{"policy", cli->out},         {"curve", r.curve.string()},
                                {"task", task->spec().name},  {"controller", cli->controller},
                                {"best_round", r.best_round}, {"rounds", rounds},
                                {"seconds", r.seconds}}
                     .dump(2)
              << "\n";
    exit_code = 0;
  });
}

}  // namespace

void AddTrainCommands(CLI::App& parent, int& exit_code) {
  auto* train = parent.add_subcommand("train", "learn policies");
  train->require_subcommand(1);
  auto cli = std::make_shared<BcCli>();
  auto* bc = train->add_subcommand(
      "bc", "behaviour cloning on demos' point clouds and proprioception (JSON report)");
  bc->add_option("--demos", cli->demos, "demos HDF5 (demos record --out)")
      ->required()
      ->check(CLI::ExistingFile);
  bc->add_option("--out", cli->out, "policy file to write; its loss curve goes beside it (.csv)")
      ->required();
  bc->add_option("--points", cli->options.sampling.n, "points per observation")
      ->check(kPointCountRange);
  bc->add_option("--epochs", cli->options.max_epochs, "at most this many epochs")
      ->check(CLI::PositiveNumber);
  bc->add_option("--patience", cli->options.patience,
                 "stop after this many epochs without a better validation loss")
      ->check(CLI::PositiveNumber);
  bc->add_option("--batch", cli->options.batch, "minibatch size")->check(CLI::PositiveNumber);
  bc->add_option("--lr", cli->options.learning_rate, "Adam learning rate")
      ->check(CLI::Range(1e-6, 1.0));
  bc->add_option("--seed", cli->options.seed, "seed");
  bc->add_option("--threads", cli->options.threads,
                 "worker threads (the result does not depend on them)")
      ->check(CLI::PositiveNumber);
  bc->callback([cli, &exit_code] {
    core::Progress progress("bc", cli->options.max_epochs, "epochs");
    const learn::BcReport r = learn::TrainBc(cli->demos, cli->out, cli->options, &progress);
    progress.Finish();
    const nlohmann::json report = {{"policy", cli->out},
                                   {"curve", r.curve.string()},
                                   {"train_steps", r.train_samples},
                                   {"valid_steps", r.valid_samples},
                                   {"epochs", r.epochs},
                                   {"best_epoch", r.best_epoch},
                                   {"best_valid_loss", r.best_valid_loss},
                                   {"final_train_loss", r.final_train_loss},
                                   {"valid_accuracy", r.valid_accuracy},
                                   {"valid_mse", r.valid_mse},
                                   {"seconds", r.seconds}};
    std::cout << report.dump(2) << "\n";
    exit_code = 0;
  });
  AddInverseDistill(*train, exit_code);
  AddRl(*train, exit_code);
  AddDistill(*train, exit_code);
  AddImitate(*train, exit_code);
  AddExport(*train, exit_code);
  auto bench_options = std::make_shared<learn::LearnBenchOptions>();
  auto* bench = train->add_subcommand(
      "bench", "PPO update and point-cloud BC throughput vs this machine's matmul peak (JSON)");
  bench->add_option("--repeats", bench_options->repeats, "runs per measurement (median)")
      ->check(CLI::PositiveNumber);
  bench->add_option("--points", bench_options->cloud_points, "points per cloud in the BC step")
      ->check(kPointCountRange);
  bench->callback([bench_options, &exit_code] {
    std::cout << learn::RunLearnBench(*bench_options).dump(2) << "\n";
    exit_code = 0;
  });
}

}  // namespace twinforge::app
