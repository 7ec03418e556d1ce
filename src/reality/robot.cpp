#include "reality/robot.h"

#include "core/error.h"

namespace twinforge::reality {

const char* ToString(SuccessAnswer answer) {
  switch (answer) {
    case SuccessAnswer::kSuccess:
      return "success";
    case SuccessAnswer::kFailure:
      return "failure";
    case SuccessAnswer::kUnknown:
      return "unknown";
  }
  return "unknown";
}

const char* ToString(OperatorInput::Kind kind) {
  switch (kind) {
    case OperatorInput::Kind::kAction:
      return "action";
    case OperatorInput::Kind::kIdle:
      return "idle";
    case OperatorInput::Kind::kDone:
      return "done";
    case OperatorInput::Kind::kQuit:
      return "quit";
  }
  return "idle";
}

RgbdFrame Robot::Capture(const CaptureRequest&) {
  throw core::Error(Info().name +
                    " cannot take scan frames (it has no camera it can move); capture the scan "
                    "with a hand-held camera and write the frames in the layout of docs/scan.md");
}

OperatorInput Robot::AskOperator() {
  throw core::Error(Info().name +
                    " has no operator of its own; record demos with --operator keyboard");
}

std::filesystem::path RobotDescriptionPath(const std::string& name) {
  const auto path = std::filesystem::path(TWINFORGE_ASSETS_DIR) / "robots" / name / "robot.yaml";
  if (!std::filesystem::is_regular_file(path))
    throw core::ConfigError(path.string(), "robot",
                            "the robot calls itself '" + name + "' but there is no " +
                                path.string() + " describing it");
  return path;
}

ActionClient::ActionClient(Robot& robot, const sim::ActionLimits& limits,
                           const SafetyLimits& safety)
    : robot_(robot),
      limits_(limits),
      filter_(safety),
      kinematics_(sim::LoadRobotSpec(RobotDescriptionPath(robot.Info().robot))) {}

FilterResult ActionClient::Act(const sim::Action& action, const Observation& observation,
                               std::optional<double> now) {
  const double age = now ? *now - observation.stamp : 0.0;
  // The tool pose the filter reasons about is the kinematic one, as the IK below sees it.
  const core::Pose tool = kinematics_.EePose(observation.q);
  FilterResult result = filter_.Filter(action, tool, limits_, gripper_, age);
  const sim::JointTargets targets =
      sim::ActionToJointTargets(kinematics_, observation.q, result.action, limits_, gripper_);
  gripper_.closure = targets.closure;
  robot_.SendTargets(targets);
  return result;
}

}  // namespace twinforge::reality
