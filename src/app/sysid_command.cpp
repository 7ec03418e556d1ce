#include "app/sysid_command.h"

#include <spdlog/spdlog.h>

#include <iostream>
#include <memory>

#include "app/reality_cli.h"
#include "core/config.h"
#include "core/error.h"
#include "core/progress.h"
#include "pipeline/twin_sysid.h"
#include "real2sim/calibrate/robot_sysid.h"

namespace twinforge::app {

namespace {

struct SysidCli {
  std::string twin, task, out, config, recorded;
  int threads = 0;  // 0: the machine's
  RealityCli reality;
  real2sim::RobotSysidOptions options;
};

void RunSysid(SysidCli& o) {
  const std::filesystem::path twin = o.twin;
  const sim::TaskSpec twin_task = sim::LoadTaskSpec((twin / "task.yaml").string());
  if (!o.task.empty() && twin_task.name != o.task)
    throw core::ConfigError((twin / "task.yaml").string(), "name",
                            "the twin is of task '" + twin_task.name + "', not '" + o.task + "'");
  core::Progress progress("sysid", 0, "replays");
  core::Json report;
  if (!o.recorded.empty()) {
    spdlog::info("sysid: fitting the runs recorded in {}", o.recorded);
    report = pipeline::IdentifyTwin(pipeline::LoadSysidRecording(o.recorded), twin, o.out,
                                    o.options, &progress);
  } else {
    reality::RealityConnection connection(o.reality.Options());
    spdlog::info("sysid: on {}", connection.address());
    report = pipeline::IdentifyTwin(connection.robot(), twin, o.out, o.options, &progress);
  }
  progress.Finish();
  std::cout << report.dump(2) << "\n";
}

}  // namespace

void AddSysidCommand(CLI::App& parent, int& exit_code) {
  auto cli = std::make_shared<SysidCli>();
  auto* sysid = parent.add_subcommand(
      "sysid",
      "identify the twin's physics from trajectories recorded on the robot: the arm's controller "
      "from free moves, then the moving parts' damping, friction and mass from task runs; writes "
      "the refined twin");
  sysid->add_option("--twin", cli->twin, "twin directory (twin build --task ..., or calibrate)")
      ->required()
      ->check(CLI::ExistingDirectory);
  sysid->add_option("--task", cli->task, "the twin's task (a check: it must be the twin's)");
  sysid->add_option("--out", cli->out, "refined twin directory to write")->required();
  sysid->add_option("--config", cli->config, "sysid options (JSON/YAML)")->check(CLI::ExistingFile);
  sysid
      ->add_option("--recorded", cli->recorded,
                   "fit the runs an earlier sysid recorded (its sysid/trajectories.json) instead "
                   "of recording on the robot")
      ->check(CLI::ExistingFile);
  sysid
      ->add_option("--threads", cli->threads,
                   "replays run at once (default: the machine's threads; the fit does not depend "
                   "on it)")
      ->check(CLI::PositiveNumber);
  cli->reality.Add(sysid);
  sysid->callback([cli, &exit_code] {
    if (!cli->config.empty())
      cli->options = core::LoadConfig<real2sim::RobotSysidOptions>(cli->config);
    cli->options.threads = cli->threads;
    RunSysid(*cli);
    exit_code = 0;
  });
}

}  // namespace twinforge::app
