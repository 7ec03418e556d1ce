// SAM-RL's residual on any base actor at a robot's controls: the base (a point-cloud policy, or
// the twin actor) proposes an action and says what it read to choose it (its features); the
// residual, an OffPolicyAgent in residual mode, reads those features and the proposal, and adds
// its bounded delta. An agent not in residual mode replaces the proposal: TD3 or SAC from scratch
// on the same inputs, the baselines.
//
// Includes <torch/torch.h> (via learn): include it only from .cpp files and tests.
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "core/rng.h"
#include "learn/offpolicy.h"
#include "reality/robot.h"
#include "reality/teleop.h"

namespace twinforge::pipeline {

// A base actor the residual can sit on.
struct ResidualBase {
  reality::Operator* op = nullptr;
  std::function<void(uint64_t seed)> begin;  // before each trial
  int feature_dim = 0;
  // The features of the observation the base last chose an action from (feature_dim floats).
  std::function<void(float*)> features;
  // What the base is (its file's hash, the twin's...): a residual trained on one base is refused
  // on another. Recorded in the agent's info as "base".
  nlohmann::json identity;
};

class ResidualOperator : public reality::Operator {
 public:
  // `client` sends the actions (its gripper latch turns a discrete move into a unit action);
  // with `explore` the agent adds its exploration noise.
  ResidualOperator(const ResidualBase& base, learn::OffPolicyAgent& agent,
                   const reality::ActionClient& client, const sim::ActionLimits& limits,
                   bool explore);

  // Before each trial: the base begins too; the exploration noise follows `seed`.
  void Begin(uint64_t seed);

  // What the residual saw and did at one step: its observation, the base action and the action
  // sent, both as unit vectors (learn/residual.h).
  struct Decision {
    const float* obs;
    const float* base;
    const float* action;
  };
  std::function<void(const Decision&)> on_decision;

  reality::OperatorInput Next(const reality::Observation& o) override;
  std::string name() const override { return base_.op->name() + " + residual"; }

 private:
  ResidualBase base_;
  learn::OffPolicyAgent& agent_;
  const reality::ActionClient& client_;
  sim::ActionLimits limits_;
  bool explore_;
  core::Rng rng_{0};
  std::vector<float> obs_, proposal_, action_;
};

// Throws, naming `file`, when `agent` cannot sit on `base` (another base, or the wrong sizes).
void CheckResidualFits(learn::OffPolicyAgent& agent, const ResidualBase& base,
                       const std::string& file);

}  // namespace twinforge::pipeline
