#include "pipeline/twin_sysid.h"

#include <algorithm>
#include <vector>

#include "core/error.h"
#include "core/log.h"
#include "real2sim/export.h"
#include "real2sim/recipe.h"
#include "real2sim/twin_edit.h"
#include "real2sim/twin_spec.h"

namespace twinforge::pipeline {

namespace {

// Sends `targets` from the task's level-0 start and reads the arm after each control period.
real2sim::RobotTrajectory Record(reality::Robot& robot, const std::string& name,
                                 std::vector<sim::JointTargets> targets) {
  real2sim::RobotTrajectory t;
  t.name = name;
  t.targets = std::move(targets);
  robot.Reset({.seed = 0, .level = 0});
  for (const auto& target : t.targets) {
    robot.SendTargets(target);
    const reality::Observation o = robot.Observe(false);
    t.q.push_back(o.q);
    t.gripper_width.push_back(o.gripper_width);
  }
  t.task_success = robot.QuerySuccess() == reality::SuccessAnswer::kSuccess;
  return t;
}

core::Json ToJson(const real2sim::RobotTrajectory& t) {
  core::Json targets = core::Json::array(), q = core::Json::array();
  for (size_t i = 0; i < t.targets.size(); ++i) {
    const auto& a = t.targets[i].arm;
    targets.push_back({{"arm", std::vector<double>(a.data(), a.data() + a.size())},
                       {"finger", t.targets[i].finger}});
    q.push_back(std::vector<double>(t.q[i].data(), t.q[i].data() + t.q[i].size()));
  }
  return {{"name", t.name},
          {"task_success", t.task_success},
          {"grip_held", real2sim::GripHeld(t)},
          {"targets", targets},
          {"q", q},
          {"gripper_width", t.gripper_width}};
}

// What the twin spec lets sysid change: each moving joint's damping and dry friction, and the
// mass of the part it moves.
std::vector<real2sim::PhysicalParameter> SceneParameters(const real2sim::TwinSpec& spec) {
  using Kind = real2sim::PhysicalParameter::Kind;
  std::vector<real2sim::PhysicalParameter> out;
  for (const auto& j : spec.joints) {
    if (j.type == real2sim::JointType::kFixed) continue;
    out.push_back({Kind::kJointDamping, j.name, 0.05, 500});
    out.push_back({Kind::kJointFriction, j.name, 0.05, 200});
    out.push_back({Kind::kBodyMass, j.child, 0.05, 50});
  }
  return out;
}

// Writes the identified scene values into the spec.
void ApplyScene(real2sim::TwinSpec& spec, const std::vector<real2sim::PhysicalParameter>& scene,
                const std::vector<double>& values) {
  using Kind = real2sim::PhysicalParameter::Kind;
  for (size_t i = 0; i < scene.size(); ++i) {
    for (auto& j : spec.joints) {
      if (j.name != scene[i].name) continue;
      if (scene[i].kind == Kind::kJointDamping) j.damping = values[i];
      if (scene[i].kind == Kind::kJointFriction) j.frictionloss = values[i];
    }
    for (auto& p : spec.parts)
      if (scene[i].kind == Kind::kBodyMass && p.name == scene[i].name) p.mass = values[i];
  }
}

}  // namespace

core::Json IdentifyTwin(reality::Robot& robot, const std::filesystem::path& twin,
                        const std::filesystem::path& out,
                        const real2sim::RobotSysidOptions& options, core::Progress* progress) {
  // (A copy into itself never ends.)
  const auto twin_abs = std::filesystem::weakly_canonical(twin);
  const auto out_abs = std::filesystem::weakly_canonical(out);
  if (std::mismatch(twin_abs.begin(), twin_abs.end(), out_abs.begin(), out_abs.end()).first ==
      twin_abs.end())
    throw core::ConfigError(out.string(), "out", "a directory outside the twin " + twin.string());
  const sim::TaskSpec twin_task = sim::LoadTaskSpec((twin / "task.yaml").string());
  // A task's own scene (no twin.yaml) has only the arm's controller to identify.
  const bool has_spec = std::filesystem::exists(twin / "twin.yaml");
  real2sim::TwinSpec spec;
  if (has_spec) spec = real2sim::LoadTwinSpec(twin / "twin.yaml");
  const auto scene = SceneParameters(spec);

  // The experiments, planned in the twin.
  bool expert_success = false;
  const auto free_targets = real2sim::FreeArmTargets(twin_task);
  // At half and a third of the speed the expert planned at: at full speed the fingers chatter
  // on a handle, and the runs' error is too rough to fit (docs/calibrate.md, stop 57).
  const auto half_speed = real2sim::ExpertTargets(twin_task, 2, &expert_success);
  const auto third_speed = real2sim::ExpertTargets(twin_task, 3);
  if (!expert_success)
    spdlog::warn(
        "sysid: the scripted expert does not reach the goal in the twin; the task runs "
        "may not move the scene");

  // ... run on the robot.
  spdlog::info(
      "sysid: recording on the robot: free moves of the arm and gripper ({} steps), the task at "
      "half and a third of full speed ({} and {} steps)",
      free_targets.size(), half_speed.size(), third_speed.size());
  std::vector<real2sim::RobotTrajectory> free_moves{Record(robot, "free_arm", free_targets)};
  std::vector<real2sim::RobotTrajectory> task_runs, all_runs;
  for (auto [name, targets] :
       {std::pair{"task_half_speed", &half_speed}, std::pair{"task_third_speed", &third_speed}}) {
    auto run = Record(robot, name, *targets);
    const bool held = real2sim::GripHeld(run);
    spdlog::info("sysid: {}: the grip {} ({} the goal)", name, held ? "held" : "slipped off",
                 run.task_success ? "reached" : "did not reach");
    if (held) task_runs.push_back(run);
    all_runs.push_back(std::move(run));
  }
  if (task_runs.empty() && !scene.empty())
    spdlog::warn(
        "sysid: the grip slipped in every task run: the scene's parameters keep the "
        "twin's values");

  const auto result =
      real2sim::IdentifyRobotPhysics(twin_task, scene, free_moves, task_runs, options, progress);

  // The refined twin: a copy with the arm's controller and grip force in task.yaml, the scene's
  // values in twin.yaml and scene.xml re-exported.
  std::filesystem::create_directories(out);
  std::filesystem::copy(
      twin, out,
      std::filesystem::copy_options::recursive | std::filesystem::copy_options::overwrite_existing);
  sim::TaskSpec refined_task = twin_task;
  refined_task.control.servo = result.identified.servo;
  refined_task.control.arm_scales = result.identified.arm;
  if (result.grip_identified) refined_task.control.grip_force = result.identified.grip_force;
  real2sim::WriteTwinTask(refined_task, out);
  if (has_spec) {
    ApplyScene(spec, scene, result.identified.scene);
    real2sim::SaveTwinSpec(out / "twin.yaml", spec);
    real2sim::ExportOptions export_options;
    export_options.cameras = real2sim::ReadSceneCameras(out / "scene.xml");
    real2sim::ExportMjcf(spec, out, export_options);
  }

  core::Json report = real2sim::ToJson(result);
  core::Json recorded = core::Json::array();
  for (const auto* list : {&free_moves, &all_runs})
    for (const auto& t : *list) recorded.push_back(ToJson(t));
  std::filesystem::create_directories(out / "sysid");
  core::WriteConfigTree(out / "sysid" / "trajectories.json", recorded);
  core::WriteConfigTree(out / "sysid" / "sysid.json", report);
  return report;
}

}  // namespace twinforge::pipeline
