// `twinforge train ...`: the learning stages.
#pragma once

#include <CLI/CLI.hpp>

namespace twinforge::app {

void AddTrainCommands(CLI::App& parent, int& exit_code);

}  // namespace twinforge::app
