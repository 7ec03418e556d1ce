// twinforge: real scene -> digital twin -> robust policy -> real robot.
#include <CLI/CLI.hpp>
#include <iostream>

#include "app/data_commands.h"
#include "app/doctor.h"
#include "app/pipeline_commands.h"
#include "app/reality_commands.h"
#include "app/sim_commands.h"
#include "app/sysid_command.h"
#include "app/train_commands.h"
#include "app/twin_commands.h"
#include "core/error.h"
#include "core/log.h"
#include "learn/torch_runtime.h"

int main(int argc, char** argv) {
  using namespace twinforge;
  // OpenBLAS's kernels for this CPU, not its SSE3 fallback (see learn/torch_runtime.h).
  learn::RestartWithTheRightBlasKernels(argv);
  // Before any tensor work: one BLAS thread per process (see learn/torch_runtime.h).
  learn::PinMathThreads(1);
  learn::KeepLargeBuffers();

  CLI::App app{"twinforge: real scene -> digital twin -> robust policy -> real robot"};
  app.require_subcommand(1);
  // Logs go to stderr from the start (spdlog's own default logger writes to stdout, which
  // mixed log lines into the JSON reports the commands print there).
  std::string log_level = "info";
  core::SetupLogging(log_level);
  app.add_option("--log-level", log_level, "trace, debug, info, warn, error, critical, off")
      ->check(CLI::IsMember({"trace", "debug", "info", "warn", "error", "critical", "off"}))
      ->each([](const std::string& level) { core::SetupLogging(level); });

  auto* doctor = app.add_subcommand("doctor", "check dependencies, BLAS and threads");
  int exit_code = 0;
  doctor->callback([&] { exit_code = app::RunDoctor(std::cout); });
  app::AddSimCommands(app, exit_code);
  app::AddRealityCommands(app, exit_code);
  app::AddDataCommands(app, exit_code);
  app::AddTwinCommands(app, exit_code);
  app::AddSysidCommand(app, exit_code);
  app::AddTrainCommands(app, exit_code);
  app::AddPipelineCommands(app, exit_code);

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  } catch (const core::Error& e) {
    spdlog::error("{}", e.what());
    return 2;
  }
  return exit_code;
}
