// Simulation throughput, measured against baselines taken in the same process: raw mj_step on the
// task model (for VecEnv overhead and thread scaling), raw mj_ray and raw Embree ray casts (for
// cloud rendering: the clouds are cast with Embree; mj_ray shows what that gains).
#pragma once

#include <memory>
#include <nlohmann/json.hpp>

#include "sim/task.h"

namespace twinforge::sim {

struct BenchOptions {
  int repeats = 5;  // medians over this many runs
  int num_envs = 8;
  int control_steps = 50;  // per VecEnv run
  int raw_steps = 8000;    // per raw mj_step run
  int clouds = 100;        // per cloud run
};

// Runs every measurement and returns them as JSON (rates per second, medians of `repeats`).
nlohmann::json RunSimBench(std::shared_ptr<const Task> task, const BenchOptions& options);

}  // namespace twinforge::sim
