// `twinforge eval` (a policy on reality, RialTo's protocol) and `twinforge run` (the main job).
#pragma once

#include <CLI/CLI.hpp>

namespace twinforge::app {

void AddPipelineCommands(CLI::App& parent, int& exit_code);

}  // namespace twinforge::app
