// Recording demonstrations on a robot (real or proxy) into a robomimic-layout HDF5 file, and
// replaying them.
//
// Per step, under data/demo_<i>/ (core/dataset.h):
//   actions            [T, 1] discrete move index (0..13), or [T, 7] continuous action
//   obs/proprio        [T, 9]  tool position, quaternion (w, x, y, z; x >= 0), finger positions
//   obs/joint_positions [T, 7]
//   obs/scene_points   [T, N, 3] from the camera's depth, arm removed, workspace-cropped
//   obs/arm_points     [T, M, 3] on the arm at its measured joints (forward kinematics)
//   rewards [T] (1 on the last step of a success), dones [T]
//   attrs meta: {seed, level, attempt, operator_seconds, keys}
// data.attrs env_args: {task, robot, source, action_mode, limits, scene_points, arm_points,
// camera}. Only successful demos are kept; every fifth goes to mask/valid.
#pragma once

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "core/dataset.h"
#include "core/progress.h"
#include "reality/frame_cloud.h"
#include "reality/robot.h"
#include "reality/teleop.h"
#include "sim/task.h"

namespace twinforge::reality {

struct RecordOptions {
  int demos = 15;        // successful demos to keep
  int max_attempts = 0;  // 0: 3 x demos
  int level = 1;         // reset level asked of the robot
  uint64_t seed = 1;     // attempt a is reset with MixSeed(seed, a)
  int valid_every = 5;   // every n-th kept demo goes to mask/valid (0: none)
  FrameCloud::Options cloud;
  bool append = false;  // add to an existing file instead of refusing to overwrite it
};

struct RecordReport {
  int attempts = 0;
  int kept = 0;
  long steps = 0;               // actions sent, in kept and dropped demos
  double operator_seconds = 0;  // time the operator took (a person at a keyboard)
  double wall_seconds = 0;
};

// Records until `demos` successes or `max_attempts`. Success comes from the robot's oracle, or
// else the operator's judgement; failed demos are dropped. Each kept demo is written as soon as
// it ends, so an interruption loses at most the demo in progress. Stops early (keeping what is
// written) when the operator quits.
RecordReport RecordDemos(Robot& robot, Operator& op, const sim::TaskSpec& task,
                         const RecordOptions& options, const std::filesystem::path& out,
                         core::Progress* progress = nullptr);

// Resets the robot the way a recorded demo began and sends its actions again. Returns the
// robot's success answer at the end.
SuccessAnswer ReplayDemo(Robot& robot, const sim::TaskSpec& task, const core::Episode& demo);

// The action stored in row `t` of a demo's actions.
sim::Action StoredAction(const core::Episode& demo, std::size_t t);

}  // namespace twinforge::reality
