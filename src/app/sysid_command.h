// `twinforge sysid`: identify the twin's physics (the arm's controller, a drawer's damping,
// friction and mass...) from trajectories recorded on the robot.
#pragma once

#include <CLI/CLI.hpp>

namespace twinforge::app {

void AddSysidCommand(CLI::App& parent, int& exit_code);

}  // namespace twinforge::app
