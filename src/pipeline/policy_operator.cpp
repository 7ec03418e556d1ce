#include "pipeline/policy_operator.h"

#include "core/error.h"
#include "learn/bc.h"
#include "sim/env.h"

namespace twinforge::pipeline {

learn::PolicyNet LoadRobotPolicy(const std::filesystem::path& path, const sim::TaskSpec& task) {
  learn::PolicyNet net = learn::LoadPolicy(path);
  if (net->config().point_features == 0)
    throw core::Error(path.string() +
                      ": a state policy needs the privileged state, which a robot does not have; "
                      "distil it into a point-cloud policy first (`train distill`)");
  sim::Task sim_task(task);
  learn::CheckPolicyFitsTask(net->config(), sim_task, path.string());
  net->eval();
  return net;
}

PolicyOperator::PolicyOperator(reality::Robot& robot, learn::PolicyNet& net,
                               const sim::TaskSpec& task, int scene_points, int arm_points,
                               bool sample, bool oracle)
    : robot_(robot),
      net_(net),
      oracle_(oracle),
      cloud_(sim::LoadRobotSpec(reality::RobotDescriptionPath(robot.Info().robot)), task.workspace,
             {scene_points, arm_points}, sim::CorrectionPose(task.camera.correction)),
      scene_(3 * scene_points),
      arm_(3 * arm_points) {
  choose_.sample = sample;
  sampling_.n = net->config().points;
  points_ = torch::empty({1, sampling_.n, 4});
  proprio_ = torch::empty({1, sim::kProprioDim});
}

void PolicyOperator::Begin(uint64_t seed) { rng_ = core::Rng(seed, 0xe7a1); }

reality::OperatorInput PolicyOperator::Next(const reality::Observation& o) {
  reality::OperatorInput in;
  if (oracle_ && robot_.QuerySuccess() == reality::SuccessAnswer::kSuccess) {
    in.kind = reality::OperatorInput::Kind::kDone;
    return in;
  }
  if (o.frames.empty()) throw core::Error("the robot sent an observation without a camera frame");
  torch::NoGradGuard no_grad;
  cloud_.Make(o, o.frames.front(), rng_, scene_.data(), arm_.data());
  learn::SamplePoints(scene_.data(), int(scene_.size() / 3), arm_.data(), int(arm_.size() / 3),
                      sampling_, false, rng_, points_.data_ptr<float>());
  sim::MakeProprio(o.ee, 0.5 * o.gripper_width, 0.5 * o.gripper_width, proprio_.data_ptr<float>());
  in.kind = reality::OperatorInput::Kind::kAction;
  // The encoder runs once: a residual reads the same features the head does.
  const torch::Tensor features = net_->HeadInput(points_, proprio_).contiguous();
  in.action = learn::ChooseAction(net_, net_->Head(features), choose_, rng_);
  features_.assign(features.data_ptr<float>(), features.data_ptr<float>() + features.numel());
  return in;
}

ResidualBase PolicyResidualBase(PolicyOperator& op, const std::string& policy_hash) {
  return {&op, [&op](uint64_t seed) { op.Begin(seed); }, op.feature_dim(),
          [&op](float* out) { std::copy(op.features().begin(), op.features().end(), out); },
          nlohmann::json{{"policy_hash", policy_hash}}};
}

}  // namespace twinforge::pipeline
