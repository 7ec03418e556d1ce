#include "pipeline/policy_operator.h"

#include "core/error.h"
#include "learn/bc.h"
#include "learn/residual.h"
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
      limits_(task.control.limits),
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

void PolicyOperator::SetResidual(learn::OffPolicyAgent* residual,
                                 const reality::ActionClient* client, bool explore) {
  if (residual && residual->obs_dim() != net_->HeadInputDim())
    throw core::Error("the residual reads " + std::to_string(residual->obs_dim()) +
                      " features, the policy gives " + std::to_string(net_->HeadInputDim()) +
                      ": it was trained on another base policy");
  if (residual && residual->action_dim() != sim::kContinuousActionDim)
    throw core::Error("the residual acts in " + std::to_string(residual->action_dim()) +
                      " dimensions, not the 7 of an end-effector action");
  if (residual && !client) throw core::Error("a residual needs the action client's gripper latch");
  residual_ = residual;
  client_ = client;
  explore_ = explore;
  obs_.resize(net_->HeadInputDim());
  base_.resize(sim::kContinuousActionDim);
  action_.resize(sim::kContinuousActionDim);
}

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
  // The encoder runs once: the residual reads the same features the head does.
  const torch::Tensor features = net_->HeadInput(points_, proprio_).contiguous();
  in.action = learn::ChooseAction(net_, net_->Head(features), choose_, rng_);
  if (!residual_) return in;
  std::copy_n(features.data_ptr<float>(), obs_.size(), obs_.data());
  learn::ToUnitAction(in.action, limits_, client_->gripper(), base_.data());
  residual_->Act(obs_.data(), base_.data(), explore_, rng_, action_.data());
  in.action = learn::FromUnitAction(action_.data(), limits_);
  if (on_decision) on_decision({obs_.data(), base_.data(), action_.data()});
  return in;
}

}  // namespace twinforge::pipeline
