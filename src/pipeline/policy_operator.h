// A point-cloud policy at a robot's controls: it turns each observation into the policy's clouds
// (camera frame back-projected, the arm from forward kinematics) and proprioception, and says
// "done" as soon as the robot's oracle reports success. With a residual (SAM-RL), the residual
// adds its delta to the policy's action (to the components it was made for), and each decision can
// be handed to a listener (the residual's trainer records transitions from it).
//
// Includes <torch/torch.h> (via learn): include it only from pipeline's .cpp files and tests.
#pragma once

#include <functional>
#include <vector>

#include "learn/offpolicy.h"
#include "learn/policy_net.h"
#include "learn/rollout.h"
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

  // A residual on the policy's actions (null: none). It reads the gripper latch from `client`
  // (the one that sends the actions); with `explore` it adds its exploration noise. An agent not
  // in residual mode replaces the policy's action (a from-scratch baseline on the same inputs).
  void SetResidual(learn::OffPolicyAgent* residual, const reality::ActionClient* client,
                   bool explore);

  // What the residual saw and did at one step: its observation, the base action and the action
  // sent, both as unit vectors (learn/residual.h).
  struct Decision {
    const float* obs;
    const float* base;
    const float* action;
  };
  std::function<void(const Decision&)> on_decision;

  // The residual's observation size for policy `net`: its head input.
  static int ResidualObsDim(learn::PolicyNet& net) { return net->HeadInputDim(); }

  reality::OperatorInput Next(const reality::Observation& o) override;
  std::string name() const override { return "policy"; }

 private:
  reality::Robot& robot_;
  learn::PolicyNet& net_;
  sim::ActionLimits limits_;
  bool oracle_;
  reality::FrameCloud cloud_;
  std::vector<float> scene_, arm_;
  learn::PolicyEvalOptions choose_;
  learn::PointSampling sampling_;
  torch::Tensor points_, proprio_;
  core::Rng rng_{0};
  learn::OffPolicyAgent* residual_ = nullptr;
  const reality::ActionClient* client_ = nullptr;
  bool explore_ = false;
  std::vector<float> obs_, base_, action_;
};

}  // namespace twinforge::pipeline
