#include "sim/task.h"

#include <algorithm>
#include <sstream>

#include "core/config.h"
#include "core/error.h"
#include "sim/mjcf.h"
#include "sim/servo_lag.h"

namespace twinforge::sim {

namespace {

std::filesystem::path TasksDir() { return std::filesystem::path(TWINFORGE_ASSETS_DIR) / "tasks"; }

// Mocap boxes parked out of the way; the env places the ones a level-2 episode uses.
std::string DistractorBodies(int count) {
  std::ostringstream xml;
  for (int i = 0; i < count; ++i)
    xml << "<body name=\"distractor_" << i << "\" mocap=\"true\" pos=\"" << 10 + i
        << " 10 -5\"><geom name=\"distractor_" << i
        << "\" type=\"box\" size=\"0.03 0.03 0.03\" rgba=\"0.5 0.5 0.5 1\" group=\"3\"/></body>";
  return xml.str();
}

}  // namespace

TaskSpec LoadTaskSpec(const std::string& name_or_path) {
  // A file; a directory holding task.yaml (a twin's); else a built-in task's name.
  std::filesystem::path path(name_or_path);
  if (std::filesystem::is_directory(path)) path /= "task.yaml";
  if (!std::filesystem::is_regular_file(path) &&
      std::filesystem::is_regular_file(TasksDir() / name_or_path / "task.yaml"))
    path = TasksDir() / name_or_path / "task.yaml";
  if (!std::filesystem::is_regular_file(path)) {
    std::string known;
    for (const auto& t : BuiltinTasks()) known += (known.empty() ? "" : ", ") + t;
    throw core::IoError("no task file or built-in task named '" + name_or_path +
                        "' (built-in tasks: " + known + ")");
  }
  TaskSpec spec = core::LoadConfig<TaskSpec>(path);
  spec.file = std::filesystem::absolute(path);
  return spec;
}

std::vector<std::string> BuiltinTasks() {
  std::vector<std::string> names;
  if (!std::filesystem::is_directory(TasksDir())) return names;
  for (const auto& entry : std::filesystem::directory_iterator(TasksDir()))
    if (std::filesystem::exists(entry.path() / "task.yaml"))
      names.push_back(entry.path().filename().string());
  std::sort(names.begin(), names.end());
  return names;
}

int Task::Id(mjtObj type, const std::string& name, const std::string& field) const {
  const int id = mj_name2id(model_.get(), type, name.c_str());
  if (id < 0) {
    const char* kind = type == mjOBJ_SITE    ? "site"
                       : type == mjOBJ_JOINT ? "joint"
                       : type == mjOBJ_BODY  ? "body"
                                             : "element";
    throw core::ConfigError(spec_.file.string(), field,
                            std::string("the scene has no ") + kind + " named '" + name + "'");
  }
  return id;
}

Task::Task(TaskSpec spec) : Task(std::move(spec), ModelEdit{}) {}

MjcfParts SceneWithRobot(const TaskSpec& spec, RobotSpec& robot) {
  const auto dir = spec.file.parent_path();
  robot = LoadRobotSpec(spec.robot.empty() ? DefaultRobotPath() : dir / spec.robot);
  MjcfParts parts;
  parts.robot = robot.mjcf_path();
  parts.robot_mount.translation = Eigen::Vector3d(spec.robot_position.data());
  parts.robot_mount.rotation = core::Yaw(spec.robot_yaw);
  parts.scene = dir / spec.scene;
  if (!std::filesystem::exists(parts.scene))
    throw core::ConfigError(spec.file.string(), "scene",
                            "file " + parts.scene.string() + " does not exist");
  return parts;
}

Task::Task(TaskSpec spec, const ModelEdit& edit) : spec_(std::move(spec)) {
  MjcfParts parts = SceneWithRobot(spec_, robot_);
  parts.extra_worldbody = DistractorBodies(spec_.randomization.distractors.max_count);
  parts.timestep = spec_.control.timestep;
  mjcf_ = AssembleMjcf(parts);
  model_ = LoadModelFromText(
      mjcf_, spec_.file.string() + " (assembled with " + parts.scene.filename().string() + ")");

  index_.robot = RobotIndex::Resolve(model_.get(), robot_);
  index_.robot_mount = Id(mjOBJ_BODY, "robot_mount", "robot");
  for (std::size_t i = 0; i < spec_.objects.size(); ++i)
    index_.object_bodies.push_back(
        Id(mjOBJ_BODY, spec_.objects[i], "objects[" + std::to_string(i) + "]"));
  for (std::size_t i = 0; i < spec_.joints.size(); ++i)
    index_.state_joints.push_back(
        Id(mjOBJ_JOINT, spec_.joints[i], "joints[" + std::to_string(i) + "]"));
  for (std::size_t i = 0; i < spec_.success.size(); ++i) {
    const auto& p = spec_.success[i];
    const std::string field = "success[" + std::to_string(i) + "]";
    TaskIndex::Predicate r{p.type, -1, -1, Eigen::Vector3d(p.axis.data()).normalized(),
                           p.threshold};
    switch (p.type) {
      case PredicateType::kSiteDistanceBelow:
        r.a = Id(mjOBJ_SITE, p.site_a, field + ".site_a");
        r.b = Id(mjOBJ_SITE, p.site_b, field + ".site_b");
        break;
      case PredicateType::kJointAbove:
        r.a = Id(mjOBJ_JOINT, p.joint, field + ".joint");
        break;
      case PredicateType::kAxisUpright:
        r.a = Id(mjOBJ_BODY, p.body, field + ".body");
        break;
      case PredicateType::kGripperReleased:
        break;
    }
    index_.predicates.push_back(r);
  }
  for (int i = 0; i < spec_.randomization.distractors.max_count; ++i) {
    const std::string name = "distractor_" + std::to_string(i);
    index_.distractor_bodies.push_back(Id(mjOBJ_BODY, name, "randomization.distractors"));
    index_.distractor_geoms.push_back(Id(mjOBJ_GEOM, name, "randomization.distractors"));
  }
  // Resolve every other name the file uses once, so a typo fails at load, not mid-episode, and
  // resets and experts never look names up.
  const auto& r = spec_.randomization;
  for (std::size_t g = 0; g < r.groups.size(); ++g)
    for (std::size_t b = 0; b < r.groups[g].bodies.size(); ++b) {
      const std::string field =
          "randomization.groups[" + std::to_string(g) + "].bodies[" + std::to_string(b) + "]";
      if (b == 0) index_.group_bodies.emplace_back();
      const int body = Id(mjOBJ_BODY, r.groups[g].bodies[b], field);
      index_.group_bodies.back().push_back(body);
      const bool free = model_->body_jntnum[body] == 1 &&
                        model_->jnt_type[model_->body_jntadr[body]] == mjJNT_FREE;
      if (!free && model_->body_parentid[body] != 0)
        throw core::ConfigError(spec_.file.string(), field,
                                "body '" + r.groups[g].bodies[b] +
                                    "' must have a free joint or be a child of the world body "
                                    "(move its root body instead)");
    }
  for (std::size_t d = 0; d < r.disturbances.size(); ++d) {
    const std::string field = "randomization.disturbances[" + std::to_string(d) + "]";
    TaskIndex::Disturbance ids;
    if (!r.disturbances[d].body.empty())
      ids.body = Id(mjOBJ_BODY, r.disturbances[d].body, field + ".body");
    if (!r.disturbances[d].joint.empty())
      ids.dof = model_->jnt_dofadr[Id(mjOBJ_JOINT, r.disturbances[d].joint, field + ".joint")];
    index_.disturbances.push_back(ids);
  }
  for (std::size_t s = 0; s < spec_.expert.steps.size(); ++s) {
    const auto& step = spec_.expert.steps[s];
    const std::string field = "expert.steps[" + std::to_string(s) + "]";
    TaskIndex::ExpertStepIds ids;
    if (!step.site.empty()) ids.site = Id(mjOBJ_SITE, step.site, field + ".site");
    if (!step.joint.empty()) ids.joint = Id(mjOBJ_JOINT, step.joint, field + ".joint");
    if (!step.carry.empty()) ids.carry = Id(mjOBJ_SITE, step.carry, field + ".carry");
    index_.expert_steps.push_back(ids);
  }
  ScaleArmPhysics(model_.get(), index_.robot, spec_.control.arm_scales);
  if (spec_.control.grip_force > 0)
    SetGripForce(model_.get(), index_.robot, spec_.control.grip_force);
  if (edit) edit(model_.get(), index_);
}

}  // namespace twinforge::sim
