// System identification of a twin against its robot: the arm's low-level controller (servo
// latency and interpolation, gain, damping and dry-friction scales) and the scene's physical
// parameters (a drawer's damping, dry friction and mass...) that make the twin's arm move as the
// real one did under the same joint targets.
//
// Two kinds of experiment, both open loop from the task's level-0 start so that robot and twin
// begin alike:
// - free moves: each joint stepped out and back in turn, then the gripper closed on nothing and
//   opened; the arm's moves fix the controller, how fast the fingers close the grip force;
// - task runs: the task's scripted expert run in the twin (say, grasp and pull the drawer), its
//   joint targets replayed on the robot, at half and at a third of the speed it planned them at
//   (at full speed the fingers chatter on a handle, and the error is too rough); with the
//   controller known, how the arm lagged while pulling tells the scene's parameters.
// The real arm's joint positions after every control period are what is matched.
#pragma once

#include <Eigen/Dense>
#include <memory>
#include <string>
#include <vector>

#include "core/config.h"
#include "core/progress.h"
#include "real2sim/calibrate/sysid.h"
#include "sim/servo_lag.h"
#include "sim/task.h"

namespace twinforge::real2sim {

struct RobotTrajectory {
  std::string name;
  std::vector<sim::JointTargets> targets;  // one per control period
  std::vector<sim::ArmVector> q;           // measured after each
  std::vector<double> gripper_width;       // measured after each (m)
  bool task_success = false;               // the task's goal was reached (robot's answer)
  // The first step compared with the twin's (the earlier ones are replayed, not compared): a
  // lift run is fitted where the object hangs still in the hand, after the grasp, whose contacts
  // hold the scan's errors (docs/calibrate.md, stop 65).
  long fit_from = 0;
};

// Whether the gripper still held something (> 5 mm between the fingers) at the last step it was
// commanded closed. A task run whose grip slipped off says little about what it pulled.
bool GripHeld(const RobotTrajectory& t);

// The arm's controller and physics as the twin models them, the fingers' force limit, and the
// values of `scene` parameters (in their order).
struct RobotPhysics {
  sim::ServoLagSpec servo;
  sim::ArmPhysicsScales arm;
  double grip_force = 0;  // N
  std::vector<double> scene;
};

// Free moves: from the level-0 start, each joint in turn is commanded `amplitude` rad out
// (toward the side that keeps the tool higher) for `hold` control periods, then back; then the
// gripper is commanded shut for `hold` periods and open again for `hold` (closing on nothing, the
// fingers move as fast as their force limit lets them).
std::vector<sim::JointTargets> FreeArmTargets(const sim::TaskSpec& twin, double amplitude = 0.15,
                                              int hold = 6);
// The scripted expert's joint targets in the twin from the level-0 start, planned at full speed,
// each sent `repeat` times (2: half speed, along the same path); `success` says whether the
// expert reached the goal in the twin.
std::vector<sim::JointTargets> ExpertTargets(const sim::TaskSpec& twin, int repeat,
                                             bool* success = nullptr);
// The same up to the end of the script's first step that carries a site (the held object lifted
// clear), then the last target held for `hold` control periods: with the arm still, how far it
// sags under what it holds tells that object's mass. Empty if no step carries.
std::vector<sim::JointTargets> LiftTargets(const sim::TaskSpec& twin, int repeat, int hold);

// The twin, replaying joint targets from the level-0 start with given physics.
class TwinReplay {
 public:
  explicit TwinReplay(const sim::TaskSpec& twin);
  // The arm's positions after each target, with `physics` (`scene` parameters set by name), and
  // if `gripper_width` is given the gripper's opening after each.
  std::vector<sim::ArmVector> Run(const RobotPhysics& physics,
                                  const std::vector<PhysicalParameter>& scene,
                                  const std::vector<sim::JointTargets>& targets,
                                  std::vector<double>* gripper_width = nullptr);
  // The twin's joint positions minus the measured ones, every step (from each one's `fit_from`)
  // and joint of every trajectory.
  Eigen::VectorXd Residuals(const RobotPhysics& physics,
                            const std::vector<PhysicalParameter>& scene,
                            const std::vector<RobotTrajectory>& trajectories);
  // The twin's gripper opening minus the measured one (m), every step of every trajectory.
  Eigen::VectorXd GripperResiduals(const RobotPhysics& physics,
                                   const std::vector<PhysicalParameter>& scene,
                                   const std::vector<RobotTrajectory>& trajectories);
  // Mean squared joint-position error (rad^2) against the trajectories.
  double Error(const RobotPhysics& physics, const std::vector<PhysicalParameter>& scene,
               const std::vector<RobotTrajectory>& trajectories);
  // The twin's robot model's own grip force (N).
  double NominalGripForce() const;
  // The twin's own values of `scene`.
  std::vector<double> NominalScene(const std::vector<PhysicalParameter>& scene) const;

 private:
  // The twin's joint positions (or with `gripper` its gripper opening) minus the measured ones.
  Eigen::VectorXd Compare(const RobotPhysics& physics, const std::vector<PhysicalParameter>& scene,
                          const std::vector<RobotTrajectory>& trajectories, bool gripper);

  std::shared_ptr<const sim::Task> task_;
  sim::Env env_;
};

struct RobotSysidOptions {
  // Levenberg-Marquardt iterations and central-difference steps (log space) of each stage.
  SysidOptions controller{.iterations = 25, .difference = 0.02};
  SysidOptions scene{.iterations = 25, .difference = 0.02};
  // The scene's global search before its Levenberg-Marquardt (0 generations: none).
  SysidOptions scene_search{
      .method = SysidOptions::Method::kCmaEs, .iterations = 40, .population = 10, .sigma = 0.5};
  double max_relative_error = 0.15;
  // The scene's values are identified only if with them the task runs are fitted to within this
  // (RMS over joints and steps, deg), or to within 3 times the free moves' fit where that is
  // worse: a fit that leaves more unexplained fits something the model lacks (a handle the scan
  // got wrong), and its error bars mean nothing. (The proxy drawer's runs fit to 2.6e-4 deg with
  // the world's own geometry; with its scanned twin to 0.033 deg, and with that twin calibrated
  // to 0.007-0.009 deg, at values 17-80% off the hidden ones: docs/calibrate.md, stop 58.)
  double max_task_rms_deg = 0.003;
  // Replays run at once, one twin each (0: the machine's hardware threads). The fit does not
  // depend on it, so it is not part of the options a run is keyed on (not serialized).
  int threads = 0;
  template <class A>
  void Serialize(A& a) {
    a("controller_iterations", controller.iterations);
    a("scene_iterations", scene.iterations);
    a("scene_search_generations", scene_search.iterations);
    a("max_relative_error", max_relative_error);
    a("max_task_rms_deg", max_task_rms_deg);
    a.Require(controller.iterations > 0, "controller_iterations", "a positive count");
    a.Require(scene.iterations > 0, "scene_iterations", "a positive count");
    a.Require(scene_search.iterations >= 0, "scene_search_generations", "a count, 0 or more");
    a.Require(max_relative_error > 0, "max_relative_error", "a positive fraction");
    a.Require(max_task_rms_deg > 0, "max_task_rms_deg", "a positive angle");
  }
};

struct RobotSysidResult {
  RobotPhysics start, identified;
  std::vector<PhysicalParameter> scene;
  double free_error_before = 0, free_error_after = 0;  // rad^2, free-arm moves
  // The gripper's opening in the free moves (m^2); the grip force's relative standard error (0
  // when the moves never closed the gripper) and whether it is identified (within
  // `max_relative_error`; if not, the twin's is kept).
  double grip_error_before = 0, grip_error_after = 0, grip_relative_error = 0;
  bool grip_identified = false;
  double task_error_before = 0, task_error_after = 0;  // rad^2, task runs
  std::vector<double> controller_curve, scene_curve;   // best error per iteration
  // How well the runs pin each value down: the relative standard error from the fit's curvature
  // (Gauss-Newton, log space). A scene value whose error exceeds `max_relative_error` is not
  // identified and keeps the twin's.
  // interpolation, latency, kp, kd, friction, joint damping
  std::vector<double> controller_relative_error;
  std::vector<double> scene_fitted, scene_relative_error;
  // How far the controller's misfit (the free moves' RMS) could move each value, relative: half
  // that RMS over what halving the value changes in the task runs. A value whose bound exceeds
  // `max_relative_error` is not identified: the arm is not known well enough to weigh it.
  std::vector<double> scene_controller_bound;
  // With two task runs or more: each run's own fit (one row per run). A value the rows
  // disagree on by more than `max_relative_error` of the joint fit is not identified.
  std::vector<std::vector<double>> scene_per_run;
  // Whether the fitted scene explains the runs (`max_task_rms_deg`); if not, nothing of it is
  // identified.
  bool scene_explains_runs = false;
  std::vector<bool> scene_identified;
  int replays = 0;
};

// Fits the controller to `free_moves` (starting from the twin's `control.servo` and
// `arm_scales`: the joints' damping scale too, which acts nearly as kd does), then the grip force
// to how the gripper opened and closed in them, then `scene`
// (starting from the twin's values) to `task_runs` with that controller. Either list may be empty
// (that stage is skipped). `identified.scene` holds the fitted values where they are identified,
// the twin's elsewhere.
RobotSysidResult IdentifyRobotPhysics(const sim::TaskSpec& twin,
                                      const std::vector<PhysicalParameter>& scene,
                                      const std::vector<RobotTrajectory>& free_moves,
                                      const std::vector<RobotTrajectory>& task_runs,
                                      const RobotSysidOptions& options = {},
                                      core::Progress* progress = nullptr);

core::Json ToJson(const RobotSysidResult& result);

}  // namespace twinforge::real2sim
