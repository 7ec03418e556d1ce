// `twinforge sim ...`: run, measure and look at the simulated tasks.
#pragma once

#include <CLI/CLI.hpp>

namespace twinforge::app {

// Adds `sim expert`, `sim bench` and `sim view` under `parent`; they set `exit_code`.
void AddSimCommands(CLI::App& parent, int& exit_code);

}  // namespace twinforge::app
