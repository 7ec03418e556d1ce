#include "app/pipeline_commands.h"

#include <unistd.h>

#include <iostream>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>

#include "app/reality_cli.h"
#include "app/twin_actor_cli.h"
#include "core/config.h"
#include "core/error.h"
#include "core/log.h"
#include "learn/torch_runtime.h"
#include "pipeline/main_job.h"
#include "pipeline/reality_eval.h"
#include "pipeline/residual_training.h"
#include "pipeline/run_directory.h"
#include "pipeline/sensing_q_training.h"
#include "reality/proxy_reality.h"
#include "sim/task.h"

namespace twinforge::app {

namespace {

struct EvalCli {
  RealityCli reality;
  std::string policy, task, out;
  TwinActorCli twin;
  std::vector<int> levels = {1, 2, 3};
  pipeline::RealityEvalOptions options;
  bool grader_state = false;
};

// Asks the person at the robot whether the trial succeeded (a robot without an oracle).
bool AskPerson(const pipeline::TrialRecord& t) {
  for (;;) {
    std::fprintf(stderr, "level %d trial %d: did it succeed? [y/n] ", t.level, t.trial);
    std::string answer;
    if (!std::getline(std::cin, answer))
      throw core::Error("eval: no answer on standard input for level " + std::to_string(t.level) +
                        " trial " + std::to_string(t.trial));
    if (answer == "y" || answer == "yes") return true;
    if (answer == "n" || answer == "no") return false;
  }
}

// SAM-RL's twin actor on `robot`: the twin's expert on the objects a frame shows, the frame taken
// from the view the twin says shows them best (or from the task camera's pose); with
// --residual, a residual on its actions.
pipeline::RealityEvalReport EvaluateTwinActor(reality::Robot& robot, const sim::TaskSpec& task,
                                              const EvalCli& cli,
                                              const pipeline::SuccessJudge& judge,
                                              core::Progress& progress) {
  TwinActorOnRobot actor(robot, task, cli.twin, cli.options.seed);
  return pipeline::EvaluateBaseOnReality(robot, actor.AsResidualBase(), actor.header(), task,
                                         cli.options, cli.out, judge, &progress);
}

void AddEval(CLI::App& parent, int& exit_code) {
  auto cli = std::make_shared<EvalCli>();
  auto* c = parent.add_subcommand(
      "eval",
      "run a point-cloud policy (or SAM-RL's twin actor) on reality: seeded trials per level, "
      "success from the robot's oracle or asked of you, 95% intervals; every trial logged (JSON "
      "report)");
  cli->reality.Add(c);
  c->get_option("--reality")
      ->description(
          "tcp://host:port of a robot (bridge protocol), proxy:WORLD to start a proxy-reality "
          "world, or twin: the --task's own twin simulated as a robot (its scene and controller, "
          "the depth noise calibrate measured, if any), to compare the same trials in the twin and "
          "on reality");
  c->add_option("--policy", cli->policy, "point-cloud policy (train bc / train distill)")
      ->check(CLI::ExistingFile);
  c->add_option(
       "--task", cli->task,
       "task name or task.yaml (with --actor twin: the twin's, e.g. RUN/calibrated/task.yaml)")
      ->required();
  cli->twin.Add(c);
  c->add_option("--levels", cli->levels, "randomization levels, e.g. 1,2,3")
      ->delimiter(',')
      ->check(CLI::Range(0, 3));
  c->add_option("--trials", cli->options.trials, "trials per level")->check(CLI::PositiveNumber);
  c->add_option("--seed", cli->options.seed, "trial seeds (the same for every policy compared)");
  c->add_flag("--sample", cli->options.sample, "sample the policy's moves (default: most likely)");
  c->add_option("--residual", cli->options.residual,
                "residual on the policy's (or the twin actor's) actions (train residual)")
      ->check(CLI::ExistingFile);
  c->add_option("--out", cli->out,
                "trial log (JSON lines; an existing log of the same policy is resumed)")
      ->required();
  c->add_flag("--grader-state", cli->grader_state,
              "proxy worlds only, to diagnose failures: run the world in this process and log its "
              "hidden end state (task joints, object poses, gripper, tool) with each trial");
  c->add_option("--trace", cli->options.trace,
                "also append every step of the trials run here (JSON lines: action, tool position, "
                "gripper width; the hidden state too with --grader-state)");
  c->callback([cli, &exit_code] {
    cli->options.levels = cli->levels;
    cli->twin.Check("eval", cli->policy);
    const sim::TaskSpec task = sim::LoadTaskSpec(cli->task);
    const std::string proxy = "proxy:";
    std::unique_ptr<reality::ProxyReality> world;
    std::unique_ptr<reality::RealityConnection> connection;
    if (cli->reality.address == "twin") {
      world =
          reality::ProxyReality::SimulatedTwin(task, reality::ProxyReality::Sensor::kCalibrated);
    } else if (cli->grader_state) {
      if (cli->reality.address.rfind(proxy, 0) != 0)
        throw core::Error(
            "eval --grader-state: --reality must be proxy:WORLD or twin (a real robot's "
            "scene has no hidden state to read), got " +
            cli->reality.address);
      world = std::make_unique<reality::ProxyReality>(
          reality::ResolveWorldDir(cli->reality.address.substr(proxy.size())));
    } else {
      connection = std::make_unique<reality::RealityConnection>(cli->reality.Options());
    }
    // A world in this process (the proxy's or the simulated twin) has its hidden state to read.
    if (cli->grader_state) cli->options.grader = [w = world.get()] { return w->GraderState(); };
    reality::Robot& robot = world ? static_cast<reality::Robot&>(*world) : connection->robot();
    core::Progress progress("eval", int64_t(cli->levels.size()) * cli->options.trials, "trials");
    const pipeline::SuccessJudge judge =
        ::isatty(STDIN_FILENO) ? pipeline::SuccessJudge(AskPerson) : nullptr;
    const pipeline::RealityEvalReport r =
        cli->twin.twin() ? EvaluateTwinActor(robot, task, *cli, judge, progress)
                         : pipeline::EvaluateOnReality(robot, cli->policy, task, cli->options,
                                                       cli->out, judge, &progress);
    progress.Finish();
    nlohmann::json report = pipeline::ToJson(r);
    if (cli->twin.twin()) {
      report["actor"] = "twin";
      report["look"] = cli->twin.look;
      if (!cli->twin.q.empty()) report["q"] = cli->twin.q;
    } else {
      report["policy"] = cli->policy;
    }
    if (!cli->options.residual.empty()) report["residual"] = cli->options.residual;
    report["task"] = task.name;
    report["reality"] = connection ? connection->address() : cli->reality.address;
    report["log"] = cli->out;
    std::cout << report.dump(2) << "\n";
    exit_code = 0;
  });
}

struct RunCli {
  RealityCli reality;
  std::string out, config;
  pipeline::MainJobOptions options;
};

void AddRun(CLI::App& parent, int& exit_code) {
  auto cli = std::make_shared<RunCli>();
  cli->reality.address = "";
  auto* c = parent.add_subcommand(
      "run",
      "the main job: scan, twin, demos, BC, inverse distillation, RL, distillation, evaluation on "
      "reality, report; re-running skips finished stages and resumes a killed one");
  cli->reality.Add(c);
  auto& o = cli->options;
  c->add_option("--task", o.task, "task name or task.yaml");
  c->add_option("--out", cli->out, "run directory (default: runs/TASK)");
  c->add_option("--config", cli->config,
                "options file (YAML/JSON; config.json of an earlier run); flags override it");
  c->add_option("--demos", o.demos, "real demos to record")->check(CLI::PositiveNumber);
  c->add_option("--rl-iterations", o.rl_iterations,
                "PPO + BC budget in iterations (0: none); the same teacher on any machine")
      ->check(CLI::NonNegativeNumber);
  c->add_option("--rl-minutes", o.rl_minutes,
                "wall-clock cap on PPO + BC (0: none); a teacher it stops depends on the "
                "machine's speed")
      ->check(CLI::NonNegativeNumber);
  c->add_option("--sim-demos", o.sim_demos,
                "sim demos for RL: policy (inverse distillation of the real-demo policy) or "
                "expert (the twin's scripted operator, for tasks whose real-demo policy never "
                "succeeds in the twin)")
      ->check(CLI::IsMember({"policy", "expert"}));
  c->add_option("--levels", o.levels, "evaluation levels, e.g. 1,2,3")
      ->delimiter(',')
      ->check(CLI::Range(0, 3));
  c->add_option("--trials", o.trials, "evaluation trials per level")->check(CLI::PositiveNumber);
  c->add_option("--threads", o.threads, "worker threads")->check(CLI::PositiveNumber);
  c->add_option("--seed", o.seed, "seed");
  c->add_flag("--no-co-train{false}", o.co_train,
              "distil the student on sim data alone, without the real demos (RialTo's ablation)");
  c->callback([cli, c, &exit_code] {
    pipeline::MainJobOptions o = cli->options;
    if (!cli->config.empty()) {
      o = core::LoadConfig<pipeline::MainJobOptions>(cli->config);
      // Flags given on the command line win over the file.
      for (const char* flag : {"--task", "--demos", "--rl-iterations", "--rl-minutes",
                               "--sim-demos", "--levels", "--trials", "--threads", "--seed",
                               "--no-co-train"})
        if (c->count(flag)) {
          const std::string f = flag;
          if (f == "--task") o.task = cli->options.task;
          if (f == "--demos") o.demos = cli->options.demos;
          if (f == "--rl-iterations") o.rl_iterations = cli->options.rl_iterations;
          if (f == "--rl-minutes") o.rl_minutes = cli->options.rl_minutes;
          if (f == "--sim-demos") o.sim_demos = cli->options.sim_demos;
          if (f == "--levels") o.levels = cli->options.levels;
          if (f == "--trials") o.trials = cli->options.trials;
          if (f == "--threads") o.threads = cli->options.threads;
          if (f == "--seed") o.seed = cli->options.seed;
          if (f == "--no-co-train") o.co_train = cli->options.co_train;
        }
    }
    if (!cli->reality.address.empty()) o.reality = cli->reality.address;
    core::Validate(o, "run's options (flags and --config)");
    const std::string task_name = sim::LoadTaskSpec(o.task).name;
    if (o.reality.empty()) o.reality = "proxy:" + task_name;
    o.token = cli->reality.token;
    const std::string out = cli->out.empty() ? "runs/" + task_name : cli->out;
    pipeline::RunMainJob(o, out);
    std::cout << nlohmann::json{{"run", out}, {"report", out + "/eval/report.html"}}.dump(2)
              << "\n";
    exit_code = 0;
  });
}

struct ResidualCli {
  RealityCli reality;
  std::string policy, task, out;
  TwinActorCli twin;
  bool fresh = false, scratch = false;
  pipeline::ResidualTrainOptions options;
};

// `train residual`: it talks to a robot, so it lives with eval rather than with the sim's
// training commands.
void AddTrainResidual(CLI::App& train, int& exit_code) {
  auto cli = std::make_shared<ResidualCli>();
  auto* c = train.add_subcommand(
      "residual",
      "SAM-RL's residual on a point-cloud policy or on the twin actor, trained on reality with TD3 "
      "or SAC from a zero start; resumes its checkpoint (JSON report)");
  cli->reality.Add(c);
  auto& o = cli->options;
  c->add_option("--policy", cli->policy, "base point-cloud policy (train distill / train bc)")
      ->check(CLI::ExistingFile);
  c->add_option(
       "--task", cli->task,
       "task name or task.yaml (with --actor twin: the twin's, e.g. RUN/calibrated/task.yaml)")
      ->required();
  cli->twin.Add(c);
  c->add_option("--out", cli->out,
                "residual file; .curve.csv, .buffer and .state.json go beside it")
      ->required();
  c->add_option("--episodes", o.episodes, "episodes on the robot")->check(CLI::PositiveNumber);
  c->add_option("--algorithm", o.agent.algorithm, "td3 or sac")
      ->check(CLI::IsMember({"td3", "sac"}));
  c->add_option("--critic-episodes", o.critic_episodes, "first episodes training the critics alone")
      ->check(CLI::NonNegativeNumber);
  c->add_option("--updates-per-step", o.updates_per_step, "gradient steps per recorded step")
      ->check(CLI::NonNegativeNumber);
  c->add_option("--scale", o.agent.residual_scale,
                "largest correction per action component (1 = one full step)")
      ->check(CLI::Range(0.01, 2.0));
  c->add_option("--noise", o.agent.exploration_noise, "TD3 exploration noise")
      ->check(CLI::Range(0.0, 1.0));
  c->add_option("--dims", o.agent.residual_dims,
                "action components corrected: 3 translation, 6 + rotation, 7 + gripper")
      ->check(CLI::Range(1, 7));
  c->add_option("--penalty", o.agent.residual_penalty, "weight on the correction's square")
      ->check(CLI::NonNegativeNumber);
  c->add_option("--level", o.level, "randomization level")->check(CLI::Range(0, 3));
  c->add_option("--seed", o.seed, "episode seeds");
  c->add_flag("--scratch", cli->scratch,
              "no residual: the agent acts alone on the same observations (a baseline)");
  c->add_flag("--fresh", cli->fresh, "discard an existing checkpoint");
  c->callback([cli, &exit_code] {
    cli->twin.Check("train residual", cli->policy);
    if (cli->scratch) cli->options.agent.residual = false;
    const sim::TaskSpec task = sim::LoadTaskSpec(cli->task);
    reality::RealityConnection connection(cli->reality.Options());
    core::Progress progress("residual", cli->options.episodes, "episodes");
    std::unique_ptr<TwinActorOnRobot> twin;
    if (cli->twin.twin())
      twin = std::make_unique<TwinActorOnRobot>(connection.robot(), task, cli->twin,
                                                cli->options.seed);
    const pipeline::ResidualTrainReport r =
        twin ? pipeline::TrainResidualOnReality(connection.robot(), twin->AsResidualBase(), task,
                                                cli->options, cli->out, cli->fresh, &progress)
             : pipeline::TrainResidualOnReality(connection.robot(), cli->policy, task, cli->options,
                                                cli->out, cli->fresh, &progress);
    progress.Finish();
    std::cout << nlohmann::json{{"residual", r.residual},
                                {"curve_csv", r.curve_csv},
                                {"base", twin ? "twin actor" : cli->policy},
                                {"task", task.name},
                                {"reality", connection.address()},
                                {"episodes", r.episodes},
                                {"successes", r.successes},
                                {"resumed_from", r.resumed_from},
                                {"transitions", r.transitions},
                                {"updates", r.updates},
                                {"seconds", r.seconds}}
                     .dump(2)
              << "\n";
    exit_code = 0;
  });
}

// `train samrl`: the sensing-aware Q from simulated episodes in the twin (no robot needed).
void AddTrainSamrl(CLI::App& train, int& exit_code) {
  struct Cli {
    std::string task, out;
    pipeline::SensingQTrainOptions options;
  };
  auto cli = std::make_shared<Cli>();
  auto* c = train.add_subcommand(
      "samrl",
      "SAM-RL's sensing-aware Q: the twin actor's simulated episodes in the twin, each look "
      "from a random view, and Q(view, the actor's next step) fitted to their returns; DIR/q.pt "
      "is what eval --actor twin --look q --q reads; resumes its episodes (JSON report)");
  auto& o = cli->options;
  c->add_option("--task", cli->task, "the twin's task name or task.yaml (e.g. RUN/twin/task.yaml)")
      ->required();
  c->add_option("--out", cli->out, "directory for episodes.*.jsonl, looks.*.jsonl, q.pt and q.json")
      ->required();
  c->add_option("--episodes", o.episodes, "simulated episodes")->check(CLI::Range(4, 100000));
  c->add_option("--max-looks", o.max_looks,
                "looks per episode at most, each from a random view (1: look once; default " +
                    std::to_string(o.max_looks) + ", eval's)")
      ->check(CLI::Range(1, 10));
  c->add_flag("--view-only{false}", o.plan,
              "Q reads the view alone, not the actor's plan (its next step) with it");
  using Return = pipeline::SensingQTrainOptions::Return;
  std::map<std::string, Return> returns;
  for (const Return r : {Return::kSuccess, Return::kCloseness, Return::kLook})
    returns[pipeline::ReturnName(r)] = r;
  c->add_option_function<std::string>(
       "--return", [&o, returns](const std::string& r) { o.ret = returns.at(r); },
       "what Q predicts: success (1 or 0), closeness (how near the twin came to success, 1 on "
       "success) or look (the share of the objects not held that the actor believed within "
       "--look-tolerance of where they stood once it had looked; default success)")
      ->check(CLI::IsMember(returns));
  c->add_option("--look-tolerance", o.look_tolerance,
                "m, in the table's plane: a belief this near counts as found (--return look)")
      ->check(CLI::PositiveNumber);
  c->add_option("--level", o.level, "the twin's randomization level")->check(CLI::Range(0, 3));
  c->add_option("--seed", o.seed, "episode seeds (and Q's initial weights)");
  c->add_option("--workers", o.workers, "threads running episodes (the episodes do not change)")
      ->check(CLI::Range(1, 64));
  c->add_option("--capture-scale", o.capture_scale,
                "the simulated frames' resolution, as a multiple of the task camera's")
      ->check(CLI::Range(1, 16));
  c->add_option("--fit-steps", o.fit.steps, "Adam steps fitting Q")->check(CLI::PositiveNumber);
  c->callback([cli, &exit_code] {
    const sim::TaskSpec task = sim::LoadTaskSpec(cli->task);
    learn::PinMathThreads(1);
    core::Progress progress("samrl", cli->options.episodes, "episodes");
    const pipeline::SensingQTrainReport r =
        pipeline::TrainSensingQ(task, cli->options, cli->out, &progress);
    progress.Finish();
    std::cout << nlohmann::json{{"q", r.q_file},
                                {"task", task.name},
                                {"episodes", r.episodes},
                                {"successes", r.successes},
                                {"looks", r.looks},
                                {"resumed_episodes", r.resumed},
                                {"valid_mse", r.fit.valid_loss},
                                {"valid_mse_of_the_mean", r.fit.valid_baseline},
                                {"view",
                                 {{"azimuth", r.chosen.azimuth},
                                  {"elevation", r.chosen.elevation},
                                  {"q", r.chosen.score}}},
                                {"seconds", r.seconds}}
                     .dump(2)
              << "\n";
    exit_code = 0;
  });
}

}  // namespace

void AddPipelineCommands(CLI::App& parent, int& exit_code) {
  AddEval(parent, exit_code);
  AddRun(parent, exit_code);
  AddTrainResidual(*parent.get_subcommand("train"), exit_code);
  AddTrainSamrl(*parent.get_subcommand("train"), exit_code);
}

}  // namespace twinforge::app
