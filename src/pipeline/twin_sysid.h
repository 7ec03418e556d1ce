// System identification of a twin on its robot, as one step: the experiments planned in the twin
// (free moves of the arm and gripper, the scripted task at half and a third of its speed), run
// on the robot, the fit (real2sim::IdentifyRobotPhysics), and the refined twin written.
// `twinforge sysid` and the main job's sysid stage both call it. The fit can also be run again
// on what an earlier run recorded, without the robot (other options, a rebuilt twin).
#pragma once

#include <filesystem>
#include <vector>

#include "core/config.h"
#include "core/progress.h"
#include "real2sim/calibrate/robot_sysid.h"
#include "reality/robot.h"

namespace twinforge::pipeline {

// Identifies the physics of the twin in `twin` (task.yaml; twin.yaml, when present, names the
// moving parts whose damping, dry friction and mass are fitted) on `robot` and writes the refined
// twin to `out`: a copy of `twin` with the identified controller in task.yaml, and the identified
// scene values in twin.yaml and scene.xml. Values the runs do not pin down keep the twin's.
// Writes out/sysid/sysid.json (the fit) and out/sysid/trajectories.json (what was recorded) and
// returns the former. `out` must lie outside `twin`.
core::Json IdentifyTwin(reality::Robot& robot, const std::filesystem::path& twin,
                        const std::filesystem::path& out,
                        const real2sim::RobotSysidOptions& options = {},
                        core::Progress* progress = nullptr);

// What sysid recorded on the robot: the free moves, and every task run (those whose grip
// slipped too; the fit leaves them out).
struct SysidRecording {
  std::vector<real2sim::RobotTrajectory> free_moves, task_runs;
};
// Reads an earlier run's out/sysid/trajectories.json; throws ConfigError naming the file, the
// run and the field that is malformed.
SysidRecording LoadSysidRecording(const std::filesystem::path& file);
// As above, fitted to `recording` instead of runs on a robot (the same twin's, or one whose
// level-0 start is the same robot's).
core::Json IdentifyTwin(const SysidRecording& recording, const std::filesystem::path& twin,
                        const std::filesystem::path& out,
                        const real2sim::RobotSysidOptions& options = {},
                        core::Progress* progress = nullptr);

}  // namespace twinforge::pipeline
