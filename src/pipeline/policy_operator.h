// A point-cloud policy at a robot's controls: it turns each observation into the policy's clouds
// (camera frame back-projected, the arm from forward kinematics) and proprioception, and says
// "done" as soon as the robot's oracle reports success. A residual (SAM-RL) sits on it through
// residual_operator.h, reading the features it keeps.
//
// Includes <torch/torch.h> (via learn): include it only from pipeline's .cpp files and tests.
#pragma once

#include <functional>
#include <vector>

#include "learn/policy_net.h"
#include "learn/rollout.h"
#include "pipeline/residual_operator.h"
#include "reality/frame_cloud.h"
#include "reality/robot.h"
#include "reality/teleop.h"

namespace twinforge::pipeline {

// A policy to run on a robot: loaded, checked against the task, in inference mode. A state
// policy is refused (a robot has no privileged state).
learn::PolicyNet LoadRobotPolicy(const std::filesystem::path& path, const sim::TaskSpec& task);

class PolicyOperator : public reality::Operator {
 public:
  PolicyOperator(reality::Robot& robot, learn::PolicyNet& net, const sim::TaskSpec& task,
                 int scene_points, int arm_points, bool sample, bool oracle);

  // Called before each trial: the point sampling and the policy's draws follow `seed`.
  void Begin(uint64_t seed);

  // The features the policy's head read at the last action (its encoder's output and the
  // proprioception): what a residual on it reads (residual_operator.h).
  int feature_dim() const { return net_->HeadInputDim(); }
  const std::vector<float>& features() const { return features_; }

  reality::OperatorInput Next(const reality::Observation& o) override;
  std::string name() const override { return "policy"; }

 private:
  reality::Robot& robot_;
  learn::PolicyNet& net_;
  bool oracle_;
  reality::FrameCloud cloud_;
  std::vector<float> scene_, arm_;
  learn::PolicyEvalOptions choose_;
  learn::PointSampling sampling_;
  torch::Tensor points_, proprio_;
  core::Rng rng_{0};
  std::vector<float> features_;
};

// `op` as the base of a residual; `policy_hash` names its policy file (Fingerprint).
ResidualBase PolicyResidualBase(PolicyOperator& op, const std::string& policy_hash);

}  // namespace twinforge::pipeline
