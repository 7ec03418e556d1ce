// sysid's replays, measured against baselines taken in the same process: raw mj_step on the
// task's model on one thread, and on two threads at once (what the machine's cores give to
// perfectly independent work: the ceiling for spreading replays over threads).
#pragma once

#include <nlohmann/json.hpp>

#include "sim/task.h"

namespace twinforge::real2sim {

struct SysidBenchOptions {
  int repeats = 5;     // medians over this many runs
  int iterations = 2;  // Levenberg-Marquardt iterations of each controller fit timed
  int raw_steps = 20000;
};

// Times a controller fit (`IdentifyRobotPhysics` on free moves of "a robot": the task's own arm,
// lagging and softer) on one thread and on two, and raw mj_step on one and two; returns the rates,
// their ratios and whether both fits came out the same (JSON).
nlohmann::json RunSysidBench(const sim::TaskSpec& task, const SysidBenchOptions& options);

}  // namespace twinforge::real2sim
