// The pose estimate's cost, measured against a baseline taken in the same process: raw
// closest-point queries (Open3D's, on one thread) of the same frame's foreground on the estimated
// objects' surfaces, the query each of the fit's ICP steps and scores makes. The frame is the
// task camera's at the resolution eval captures, from the twin run as a robot at a level's reset
// (ProxyReality::SimulatedTwin: an ideal depth sensor), so the objects' poses are known and the
// fits' errors are reported beside their times.
#pragma once

#include <cstdint>
#include <memory>
#include <nlohmann/json.hpp>

#include "sim/task.h"

namespace twinforge::samrl {

struct PoseBenchOptions {
  int repeats = 3;  // medians over this many runs
  uint64_t seed = 5000;
  int level = 1;          // the reset's randomization: 1 moves and turns the objects
  int capture_scale = 8;  // the frame at this many times the task camera's resolution, as eval's
  // The frame from the middle of the movable camera's mount (ObjectsMount: the hidden peg's far
  // side, which the task camera does not see) rather than from the task camera.
  bool from_mount = false;
};

// Times ObjectPoseEstimator::Estimate on the frame with the default options and with every
// start stepping on every point near it (PoseEstimateOptions::start_points 0), and raw
// closest-point passes over the foreground; returns the times, their ratios (the estimate in raw
// passes) and each object's fitted error (JSON).
nlohmann::json RunPoseBench(std::shared_ptr<const sim::Task> twin, const PoseBenchOptions& options);

}  // namespace twinforge::samrl
