// `twinforge reality ...`: serve a proxy world over the bridge, and talk to a robot.
#pragma once

#include <CLI/CLI.hpp>

namespace twinforge::app {

void AddRealityCommands(CLI::App& parent, int& exit_code);

}  // namespace twinforge::app
