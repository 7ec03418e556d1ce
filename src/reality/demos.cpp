#include "reality/demos.h"

#include <chrono>

#include "core/error.h"
#include "core/log.h"
#include "sim/env.h"

namespace twinforge::reality {

namespace {

// One demo's columns, filled a step at a time.
struct DemoBuffer {
  std::vector<float> actions, proprio, joints, scene, arm;
  std::size_t steps = 0;

  void Add(const Observation& o, const sim::Action& action, FrameCloud& cloud, core::Rng& rng) {
    if (action.mode == sim::ActionMode::kDiscrete)
      actions.push_back(static_cast<float>(action.index));
    else
      actions.insert(actions.end(), action.value.begin(), action.value.end());
    proprio.resize(proprio.size() + sim::kProprioDim);
    sim::MakeProprio(o.ee, 0.5 * o.gripper_width, 0.5 * o.gripper_width,
                     proprio.data() + proprio.size() - sim::kProprioDim);
    joints.insert(joints.end(), o.q.data(), o.q.data() + sim::kArmDof);
    const auto& c = cloud.options();
    scene.resize(scene.size() + 3 * c.scene_points);
    arm.resize(arm.size() + 3 * c.arm_points);
    cloud.Make(o, o.frames.front(), rng, scene.data() + scene.size() - 3 * c.scene_points,
               arm.data() + arm.size() - 3 * c.arm_points);
    ++steps;
  }

  core::Episode ToEpisode(const FrameCloud::Options& c, nlohmann::json meta) const {
    core::Episode e;
    const std::size_t t = steps;
    auto column = [t](std::vector<std::size_t> shape, const std::vector<float>& values) {
      shape.insert(shape.begin(), t);
      core::FloatArray a(shape);
      a.data = values;
      return a;
    };
    e.actions = column({actions.size() / t}, actions);
    e.obs["proprio"] = column({sim::kProprioDim}, proprio);
    e.obs["joint_positions"] = column({sim::kArmDof}, joints);
    e.obs["scene_points"] = column({std::size_t(c.scene_points), 3}, scene);
    e.obs["arm_points"] = column({std::size_t(c.arm_points), 3}, arm);
    e.rewards.assign(t, 0.0f);
    e.rewards.back() = 1.0f;
    e.dones.assign(t, 0);
    e.dones.back() = 1;
    e.meta = std::move(meta);
    return e;
  }
};

}  // namespace

sim::Action StoredAction(const core::Episode& demo, std::size_t t) {
  const float* row = demo.actions.row(t);
  if (demo.actions.row_size() == 1) return sim::Action::Discrete(static_cast<int>(row[0]));
  if (demo.actions.row_size() != sim::kContinuousActionDim)
    throw core::DatasetError("actions have " + std::to_string(demo.actions.row_size()) +
                             " columns: expected 1 (discrete) or 7 (continuous)");
  std::array<double, sim::kContinuousActionDim> v{};
  std::copy(row, row + sim::kContinuousActionDim, v.begin());
  return sim::Action::Continuous(v);
}

RecordReport RecordDemos(Robot& robot, Operator& op, const sim::TaskSpec& task,
                         const RecordOptions& options, const std::filesystem::path& out,
                         core::Progress* progress) {
  if (options.demos <= 0)
    throw core::ConfigError("demos record", "n",
                            "at least one demo, got " + std::to_string(options.demos));
  const auto start = std::chrono::steady_clock::now();
  const RobotInfo info = robot.Info();
  const sim::RobotSpec robot_spec = sim::LoadRobotSpec(RobotDescriptionPath(info.robot));
  FrameCloud cloud(robot_spec, task.workspace, options.cloud,
                   sim::CorrectionPose(task.camera.correction));
  ActionClient client(robot, task.control.limits);
  const nlohmann::json env_args = {
      {"env_name", task.name},
      {"type", "twinforge"},
      {"task", task.name},
      {"source", info.name},
      {"robot", info.robot},
      {"action_mode",
       task.control.action == sim::ActionMode::kDiscrete ? "discrete" : "continuous"},
      {"limits",
       {{"translation", task.control.limits.translation},
        {"rotation", task.control.limits.rotation}}},
      {"scene_points", options.cloud.scene_points},
      {"arm_points", options.cloud.arm_points},
      {"operator", op.name()}};
  core::DatasetWriter writer = options.append && std::filesystem::exists(out)
                                   ? core::DatasetWriter::Append(out)
                                   : core::DatasetWriter::Create(out, env_args);
  const int max_attempts = options.max_attempts > 0 ? options.max_attempts : 3 * options.demos;
  const int max_steps = 3 * task.horizon;  // a person may be slower than the task's horizon
  RecordReport report;
  for (int attempt = 0; report.kept < options.demos && attempt < max_attempts; ++attempt) {
    const uint64_t seed = core::MixSeed(options.seed, attempt);
    ++report.attempts;
    Observation o = robot.Reset({seed, options.level});
    client.ResetGripper();
    core::Rng cloud_rng(seed, 0xc10d);
    DemoBuffer demo;
    const OperatorRun run = RunOperator(
        robot, op, client, o, max_steps, true,
        [&](const Observation& seen, const sim::Action& action) {
          if (seen.frames.empty())
            throw core::Error(info.name + " sent an observation without a camera frame");
          demo.Add(seen, action, cloud, cloud_rng);
        });
    report.steps += static_cast<long>(demo.steps);
    report.operator_seconds += run.seconds;
    if (run.quit) {
      spdlog::warn("demos: the operator stopped recording; {} demos kept in {}", report.kept,
                   out.string());
      break;
    }
    SuccessAnswer answer = robot.QuerySuccess();
    if (answer == SuccessAnswer::kUnknown) answer = op.Judge();
    if (answer != SuccessAnswer::kSuccess || demo.steps == 0) {
      spdlog::info("demos: attempt {} failed after {} steps; dropped", attempt, demo.steps);
      continue;
    }
    const nlohmann::json meta = {{"seed", seed},
                                 {"level", options.level},
                                 {"attempt", attempt},
                                 {"operator_seconds", run.seconds},
                                 {"keys", demo.steps}};
    const bool valid =
        options.valid_every > 0 && report.kept % options.valid_every == options.valid_every - 1;
    writer.Add(demo.ToEpisode(options.cloud, meta),
               valid ? core::Split::kValid : core::Split::kTrain);
    ++report.kept;
    if (progress)
      progress->Set(report.kept, std::to_string(report.attempts) + " attempts, " +
                                     std::to_string(demo.steps) + " steps");
  }
  report.wall_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return report;
}

SuccessAnswer ReplayDemo(Robot& robot, const sim::TaskSpec& task, const core::Episode& demo) {
  if (!demo.meta.contains("seed") || !demo.meta.contains("level"))
    throw core::DatasetError("demo has no meta {seed, level}: it was not recorded by twinforge");
  ActionClient client(robot, task.control.limits);
  Observation o = robot.Reset({demo.meta["seed"].get<uint64_t>(), demo.meta["level"].get<int>()});
  for (std::size_t t = 0; t < demo.length(); ++t) {
    client.Act(StoredAction(demo, t), o);
    o = robot.Observe(false);
  }
  return robot.QuerySuccess();
}

}  // namespace twinforge::reality
