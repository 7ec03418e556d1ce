// `twinforge sim ...`: run, measure and look at the simulated tasks.
#pragma once

#include <CLI/CLI.hpp>

#include "sim/expert.h"

namespace twinforge::app {

// `--optimize-moves N` and `--plan-stretch S`: the scripted expert plans each free move by N iLQR
// iterations (sim::ScriptedExpert::set_planning); `sim expert`, `sim trace`, `sim view`,
// `train imitate`.
void AddOptimizeMovesOption(CLI::App& command, sim::PlanOptions& plan);

// Adds `sim expert`, `sim bench` and `sim view` under `parent`; they set `exit_code`.
void AddSimCommands(CLI::App& parent, int& exit_code);

}  // namespace twinforge::app
