#include "app/sim_commands.h"

#include <iostream>
#include <memory>

#include "core/config.h"
#include "core/thread_pool.h"
#include "sim/expert.h"
#include "sim/task.h"

namespace twinforge::app {

void AddSimCommands(CLI::App& parent, int& exit_code) {
  auto* sim = parent.add_subcommand("sim", "run, measure and look at simulated tasks");
  sim->require_subcommand(1);

  struct ExpertOptions {
    std::string task = "open_drawer";
    int episodes = 100;
    int level = 1;
    uint64_t seed = 0;
    double noise = 0.0;
    int threads = core::DefaultThreadCount();
  };
  auto expert_options = std::make_shared<ExpertOptions>();
  auto* expert = sim->add_subcommand("expert", "success rate of a task's scripted expert (JSON)");
  expert->add_option("--task", expert_options->task, "built-in task name or task.yaml path");
  expert->add_option("--episodes", expert_options->episodes, "episodes")
      ->check(CLI::PositiveNumber);
  expert->add_option("--level", expert_options->level, "randomization level 0..3")
      ->check(CLI::Range(0, 3));
  expert->add_option("--seed", expert_options->seed, "seed");
  expert->add_option("--noise", expert_options->noise, "expert action noise")
      ->check(CLI::Range(0.0, 1.0));
  expert->add_option("--threads", expert_options->threads, "worker threads")
      ->check(CLI::PositiveNumber);
  expert->callback([expert_options, &exit_code] {
    const auto& o = *expert_options;
    auto task = std::make_shared<const sim::Task>(sim::LoadTaskSpec(o.task));
    const auto report = sim::EvaluateExpert(task, o.episodes, o.level, o.seed, o.noise, o.threads);
    core::Json out = {{"task", task->spec().name},
                      {"level", o.level},
                      {"episodes", report.episodes},
                      {"successes", report.successes},
                      {"success_rate", report.success_rate()},
                      {"mean_steps_to_success", report.mean_steps_to_success},
                      {"failed_episodes", report.failed_seeds}};
    std::cout << out.dump(2) << std::endl;
    exit_code = 0;
  });

  // One expert episode, step by step, for writing and debugging task files.
  auto trace_options = std::make_shared<ExpertOptions>();
  auto* trace = sim->add_subcommand("trace", "print one expert episode step by step (JSON lines)");
  trace->add_option("--task", trace_options->task, "built-in task name or task.yaml path");
  trace->add_option("--level", trace_options->level, "randomization level 0..3")
      ->check(CLI::Range(0, 3));
  trace->add_option("--seed", trace_options->seed, "seed, as given to sim expert");
  auto episode = std::make_shared<int>(0);
  trace->add_option("--episode", *episode, "episode index (sim expert lists failed ones)");
  trace->add_option("--noise", trace_options->noise, "expert action noise");
  trace->callback([trace_options, episode, &exit_code] {
    const auto& o = *trace_options;
    auto task = std::make_shared<const sim::Task>(sim::LoadTaskSpec(o.task));
    sim::Env env(task);
    sim::ScriptedExpert expert(*task, o.noise);
    const uint64_t seed = core::MixSeed(o.seed, static_cast<uint64_t>(*episode));
    env.Reset(seed, o.level);
    core::Rng rng(seed, 0xe4);
    std::vector<float> state(env.state_dim());
    for (int t = 0; t < task->spec().horizon; ++t) {
      const sim::Action action = expert.Act(env, rng);
      const int step = expert.current_step();
      const sim::StepResult r = env.Step(action);
      env.State(state.data());
      core::Json line = {{"t", t},
                         {"expert_step", step},
                         {"action", action.mode == sim::ActionMode::kDiscrete
                                        ? core::Json(sim::DiscreteActionName(action.index))
                                        : core::Json(action.value)},
                         {"state", state},
                         {"success", r.success}};
      std::cout << line.dump() << "\n";
      if (r.success || r.done) break;
    }
    exit_code = 0;
  });
}

}  // namespace twinforge::app
