// `twinforge twin ...`: from scan frames to an articulated MuJoCo twin.
#pragma once

#include <CLI/CLI.hpp>

namespace twinforge::app {

void AddTwinCommands(CLI::App& parent, int& exit_code);

}  // namespace twinforge::app
