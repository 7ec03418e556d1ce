#include "app/sim_commands.h"

#include <fstream>
#include <iostream>
#include <memory>

#include "core/config.h"
#include "core/error.h"
#include "core/image.h"
#include "core/thread_pool.h"
#include "learn/evaluate.h"
#include "real2sim/calibrate/sysid_bench.h"
#include "samrl/pose_bench.h"
#include "sim/bench.h"
#include "sim/camera.h"
#include "sim/expert.h"
#include "sim/task.h"

namespace twinforge::app {

namespace {

struct ExpertOptions {
  std::string task = "open_drawer";
  int episodes = 100;
  int episode = 0;
  int level = 1;
  uint64_t seed = 0;
  double noise = 0.0;
  sim::PlanOptions plan;  // the expert's planned moves (ScriptedExpert::set_planning)
  int threads = core::DefaultThreadCount();
  bool all_contacts = false;  // trace: every contact, not only the robot's
};

// --task, --level, --seed, --noise, --optimize-moves, and --episode for commands that show one
// episode.
void AddEpisodeOptions(CLI::App* command, ExpertOptions& o, bool one_episode) {
  command->add_option("--task", o.task, "built-in task name or task.yaml path");
  command->add_option("--level", o.level, "randomization level 0..3")->check(CLI::Range(0, 3));
  command->add_option("--seed", o.seed, "seed");
  command->add_option("--noise", o.noise, "expert action noise")->check(CLI::Range(0.0, 1.0));
  AddOptimizeMovesOption(*command, o.plan);
  if (one_episode)
    command->add_option("--episode", o.episode, "episode index (sim expert lists failed ones)");
}

}  // namespace

void AddOptimizeMovesOption(CLI::App& command, sim::PlanOptions& plan) {
  command
      .add_option("--optimize-moves", plan.iterations,
                  "the expert plans each free move of a continuous task by this many iLQR "
                  "iterations through the twin's own dynamics and follows the plan (0: the "
                  "script's straight moves)")
      ->check(CLI::Range(0, 1000));
  command
      .add_option("--plan-stretch", plan.stretch,
                  "with --optimize-moves: a planned move takes this many times the control steps "
                  "it needs at the action limits")
      ->capture_default_str()
      ->check(CLI::Range(1.0, 10.0));
  command.add_flag("--plan-along-path", plan.along_path,
                   "with --optimize-moves: aim at the plan's pose one step past the one nearest "
                   "the tool, not at the pose for the control step the move is in");
  command
      .add_option("--plan-end-speed", plan.end_speed_weight,
                  "with --optimize-moves: the weight on the arm's joint speeds at a plan's end "
                  "(1 stops there, 0 arrives moving)")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 1e6));
}

void AddSimCommands(CLI::App& parent, int& exit_code) {
  auto* sim = parent.add_subcommand("sim", "run, measure and look at simulated tasks");
  sim->require_subcommand(1);

  auto expert_options = std::make_shared<ExpertOptions>();
  auto* expert = sim->add_subcommand("expert", "success rate of a task's scripted expert (JSON)");
  AddEpisodeOptions(expert, *expert_options, false);
  expert->add_option("--episodes", expert_options->episodes, "episodes")
      ->check(CLI::PositiveNumber);
  expert->add_option("--threads", expert_options->threads, "worker threads")
      ->check(CLI::PositiveNumber);
  expert->callback([expert_options, &exit_code] {
    const auto& o = *expert_options;
    auto task = std::make_shared<const sim::Task>(sim::LoadTaskSpec(o.task));
    const auto report =
        sim::EvaluateExpert(task, o.episodes, o.level, o.seed, o.noise, o.threads, o.plan);
    core::Json out = {{"task", task->spec().name},
                      {"level", o.level},
                      {"episodes", report.episodes},
                      {"successes", report.successes},
                      {"success_rate", report.success_rate()},
                      {"mean_steps_to_success", report.mean_steps_to_success},
                      {"planned_moves", report.plans.planned_moves},
                      {"failed_plans", report.plans.failed_plans},
                      {"failed_episodes", report.failed_seeds}};
    std::cout << out.dump(2) << std::endl;
    exit_code = 0;
  });

  // A learned policy's success rate, per level.
  struct EvalCli {
    std::string policy, task, trace;
    std::vector<int> levels{1};
    learn::PolicyEvalOptions options;
  };
  auto eval_cli = std::make_shared<EvalCli>();
  auto* eval = sim->add_subcommand(
      "eval", "success rate of a policy (train bc ...) in the sim, per level (JSON)");
  eval->add_option("--policy", eval_cli->policy, "policy file")
      ->required()
      ->check(CLI::ExistingFile);
  eval->add_option("--task", eval_cli->task, "built-in task name, task.yaml or a twin directory")
      ->required();
  eval->add_option("--levels", eval_cli->levels, "randomization levels, e.g. 1,2,3")
      ->delimiter(',')
      ->check(CLI::Range(0, 3));
  eval->add_option("--episodes", eval_cli->options.episodes, "episodes per level")
      ->check(CLI::PositiveNumber);
  eval->add_option("--seed", eval_cli->options.seed, "seed");
  eval->add_option("--threads", eval_cli->options.threads, "worker threads")
      ->check(CLI::PositiveNumber);
  eval->add_flag("--sample", eval_cli->options.sample,
                 "sample the policy's moves (as PPO trains and evaluates it) instead of taking "
                 "the most likely one");
  eval->add_option("--trace", eval_cli->trace,
                   "also write the first level's episode 0 step by step here (JSON lines: action, "
                   "privileged state, reward; then success)");
  eval->callback([eval_cli, &exit_code] {
    auto task = std::make_shared<const sim::Task>(sim::LoadTaskSpec(eval_cli->task));
    if (!eval_cli->trace.empty()) {
      learn::PolicyEvalOptions o = eval_cli->options;
      o.level = eval_cli->levels.front();
      std::ofstream out(eval_cli->trace);
      if (!out) throw core::IoError("cannot write the trace to " + eval_cli->trace);
      learn::TracePolicyEpisode(eval_cli->policy, task, o, 0, out);
    }
    core::Json levels = core::Json::array();
    for (int level : eval_cli->levels) {
      learn::PolicyEvalOptions o = eval_cli->options;
      o.level = level;
      const auto r = learn::EvaluatePolicy(eval_cli->policy, task, o);
      levels.push_back({{"level", level},
                        {"episodes", r.episodes},
                        {"successes", r.successes},
                        {"success_rate", r.success_rate()},
                        {"steps", r.steps},
                        {"seconds", r.seconds}});
    }
    std::cout << core::Json{{"policy", eval_cli->policy},
                            {"task", task->spec().name},
                            {"actions", eval_cli->options.sample ? "sampled" : "greedy"},
                            {"levels", levels}}
                     .dump(2)
              << std::endl;
    exit_code = 0;
  });

  // One expert episode, step by step, for writing and debugging task files.
  auto trace_options = std::make_shared<ExpertOptions>();
  auto* trace = sim->add_subcommand("trace", "print one expert episode step by step (JSON lines)");
  AddEpisodeOptions(trace, *trace_options, true);
  trace->add_flag("--all-contacts", trace_options->all_contacts,
                  "list every contact in `robot_contacts`, not only the robot's (a twin's part "
                  "touching its carcass or the table)");
  trace->callback([trace_options, &exit_code] {
    const auto& o = *trace_options;
    auto task = std::make_shared<const sim::Task>(sim::LoadTaskSpec(o.task));
    sim::Env env(task);
    sim::ScriptedExpert expert(*task, o.noise);
    expert.set_planning(o.plan);
    core::Rng rng = sim::BeginExpertEpisode(env, expert, o.seed, o.episode, o.level);
    std::vector<float> state(env.state_dim());
    for (int t = 0; t < task->spec().horizon; ++t) {
      const sim::Action action = expert.Act(env, rng);
      const int step = expert.current_step();
      const sim::StepResult r = env.Step(action);
      env.State(state.data());
      // What the robot touches (a twin's collision boxes are where experts get stuck).
      const mjModel* m = env.model();
      const mjData* d = env.data();
      std::vector<std::string> touches;
      for (int c = 0; c < d->ncon; ++c) {
        const int g1 = d->contact[c].geom1, g2 = d->contact[c].geom2;
        const bool r1 = m->geom_group[g1] == sim::kRobotGeomGroup,
                   r2 = m->geom_group[g2] == sim::kRobotGeomGroup;
        if (r1 == r2 && !o.all_contacts) continue;
        auto name = [m](int g) {
          const char* n = mj_id2name(m, mjOBJ_GEOM, g);
          return n ? std::string(n) : "geom " + std::to_string(g);
        };
        touches.push_back(r1 ? name(g1) + "/" + name(g2) : name(g2) + "/" + name(g1));
      }
      core::Json joints = core::Json::object();
      for (int j : task->index().state_joints)
        joints[mj_id2name(m, mjOBJ_JOINT, j)] = d->qpos[m->jnt_qposadr[j]];
      core::Json line = {{"t", t},
                         {"expert_step", step},
                         {"action", sim::ToJson(action)},
                         {"state", state},
                         {"joints", joints},
                         {"robot_contacts", touches},
                         {"success", r.success}};
      std::cout << line.dump() << "\n";
      if (r.success || r.done) break;
    }
    exit_code = 0;
  });

  // Throughput against in-process baselines.
  auto bench_task = std::make_shared<std::string>("open_drawer");
  auto bench_options = std::make_shared<sim::BenchOptions>();
  auto* bench = sim->add_subcommand("bench", "VecEnv and cloud throughput vs raw MuJoCo (JSON)");
  bench->add_option("--task", *bench_task, "built-in task name or task.yaml path");
  bench->add_option("--repeats", bench_options->repeats, "runs per measurement (median)")
      ->check(CLI::PositiveNumber);
  bench->add_option("--num-envs", bench_options->num_envs, "environments in the VecEnv")
      ->check(CLI::PositiveNumber);
  auto bench_sysid = std::make_shared<bool>(false);
  auto* sysid_flag = bench->add_flag(
      "--sysid", *bench_sysid,
      "time sysid's replays instead: a controller fit on 1 and 2 threads, against raw "
      "mj_step on 1 and 2");
  auto bench_pose = std::make_shared<samrl::PoseBenchOptions>();
  auto bench_pose_on = std::make_shared<bool>(false);
  auto* pose_flag =
      bench->add_flag("--pose", *bench_pose_on,
                      "time the pose estimate instead: on the task camera's frame of the twin at a "
                      "reset, against raw closest-point queries of the same points");
  pose_flag->excludes(sysid_flag);
  bench->add_option("--seed", bench_pose->seed, "the reset's seed (--pose)")->needs(pose_flag);
  bench->add_option("--level", bench_pose->level, "the reset's level (--pose)")
      ->check(CLI::Range(0, 3))
      ->needs(pose_flag);
  bench
      ->add_option("--capture-scale", bench_pose->capture_scale,
                   "the frame at this many times the task camera's resolution (--pose)")
      ->check(CLI::Range(1, 16))
      ->needs(pose_flag);
  bench
      ->add_flag("--from-mount", bench_pose->from_mount,
                 "the frame from the middle of the movable camera's mount, not the task camera "
                 "(--pose)")
      ->needs(pose_flag);
  bench->callback([bench_task, bench_options, bench_sysid, bench_pose, bench_pose_on, &exit_code] {
    const sim::TaskSpec spec = sim::LoadTaskSpec(*bench_task);
    if (*bench_pose_on) {
      bench_pose->repeats = bench_options->repeats;
      std::cout << samrl::RunPoseBench(std::make_shared<const sim::Task>(spec), *bench_pose).dump(2)
                << std::endl;
    } else if (*bench_sysid) {
      std::cout << real2sim::RunSysidBench(spec, {.repeats = bench_options->repeats}).dump(2)
                << std::endl;
    } else {
      auto task = std::make_shared<const sim::Task>(spec);
      std::cout << sim::RunSimBench(task, *bench_options).dump(2) << std::endl;
    }
    exit_code = 0;
  });

  // PNG frames of one expert episode, from the task camera, robot included.
  auto view_options = std::make_shared<ExpertOptions>();
  auto view_out = std::make_shared<std::string>("frames");
  auto view_size = std::make_shared<std::array<int, 2>>(std::array<int, 2>{320, 240});
  auto* view = sim->add_subcommand("view", "write PNG frames of a scripted episode");
  AddEpisodeOptions(view, *view_options, true);
  view->add_option("--out", *view_out, "output directory");
  view->add_option("--size", *view_size, "width height")->expected(2);
  view->callback([view_options, view_out, view_size, &exit_code] {
    const auto& o = *view_options;
    auto task = std::make_shared<const sim::Task>(sim::LoadTaskSpec(o.task));
    sim::CameraSpec spec = task->spec().camera;
    spec.width = (*view_size)[0];
    spec.height = (*view_size)[1];
    sim::Env env(task);
    sim::RayCaster caster(sim::MakeCamera(spec), env.model());
    sim::ScriptedExpert expert(*task, o.noise);
    expert.set_planning(o.plan);
    core::Rng rng = sim::BeginExpertEpisode(env, expert, o.seed, o.episode, o.level);
    core::Image frame{spec.width, spec.height, 3, 8,
                      std::vector<uint8_t>(std::size_t(spec.width) * spec.height * 3)};
    std::vector<float> depth(std::size_t(spec.width) * spec.height);
    int written = 0;
    bool success = false;
    for (int t = 0; t <= task->spec().horizon && !success; ++t) {
      caster.Render(env.model(), env.data(), env.base(), depth.data(), frame.bytes.data(), true);
      char name[32];
      std::snprintf(name, sizeof name, "frame_%03d.png", t);
      core::WritePng(std::filesystem::path(*view_out) / name, frame);
      ++written;
      if (t == task->spec().horizon) break;
      success = env.Step(expert.Act(env, rng)).success;
    }
    std::cout << core::Json{{"task", task->spec().name},
                            {"frames", written},
                            {"success", success},
                            {"out", *view_out}}
                     .dump()
              << std::endl;
    exit_code = 0;
  });
}

}  // namespace twinforge::app
