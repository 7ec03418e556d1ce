// `twinforge demos ...` and `twinforge scan ...`: what the pipeline collects from reality.
#pragma once

#include <CLI/CLI.hpp>

namespace twinforge::app {

void AddDataCommands(CLI::App& parent, int& exit_code);

}  // namespace twinforge::app
