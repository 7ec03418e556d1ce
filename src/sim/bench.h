// Simulation throughput, measured against baselines taken in the same process: raw mj_step on the
// task model (for VecEnv overhead and thread scaling), raw mj_ray and raw Embree ray casts (for
// cloud rendering: the clouds are cast with Embree; mj_ray shows what that gains).
#pragma once

#include <memory>
#include <nlohmann/json.hpp>

#include "sim/env.h"
#include "sim/task.h"

namespace twinforge::sim {

struct BenchOptions {
  int repeats = 5;  // medians over this many runs
  int num_envs = 8;
  int control_steps = 50;  // per VecEnv run
  int raw_steps = 8000;    // per raw mj_step run
  int clouds = 100;        // per cloud run
};

// The baseline other loops are measured against: raw mj_step on copies of `reference`'s model from
// its state, driven as an env drives it (the arm's targets jittered every control period, its
// gravity compensated) and nothing else. Physics steps per second on one thread (`one`), and on two
// threads at once, a copy each (`two`, both threads' steps counted): what this machine's cores
// give to perfectly independent work. `seed` jitters the targets.
struct RawStepRates {
  double one = 0, two = 0;
};
RawStepRates MeasureRawSteps(const Env& reference, int steps, uint64_t seed);

// Runs every measurement and returns them as JSON (rates per second, medians of `repeats`).
nlohmann::json RunSimBench(std::shared_ptr<const Task> task, const BenchOptions& options);

}  // namespace twinforge::sim
