#include "pipeline/residual_operator.h"

#include "core/error.h"
#include "learn/residual.h"
#include "sim/action.h"

namespace twinforge::pipeline {

void CheckResidualFits(learn::OffPolicyAgent& agent, const ResidualBase& base,
                       const std::string& file) {
  const nlohmann::json trained_on = agent.info().value("base", nlohmann::json());
  if (!trained_on.is_null() && trained_on != base.identity)
    throw core::Error(file + ": a residual trained on another base (" + trained_on.dump() +
                      "), not " + base.identity.dump());
  if (agent.obs_dim() != base.feature_dim)
    throw core::Error(file + ": the residual reads " + std::to_string(agent.obs_dim()) +
                      " features, the base gives " + std::to_string(base.feature_dim) +
                      ": it was trained on another base");
  if (agent.action_dim() != sim::kContinuousActionDim)
    throw core::Error(file + ": the residual acts in " + std::to_string(agent.action_dim()) +
                      " dimensions, not the 7 of an end-effector action");
}

ResidualOperator::ResidualOperator(const ResidualBase& base, learn::OffPolicyAgent& agent,
                                   const reality::ActionClient& client,
                                   const sim::ActionLimits& limits, bool explore)
    : base_(base),
      agent_(agent),
      client_(client),
      limits_(limits),
      explore_(explore),
      obs_(base.feature_dim),
      proposal_(sim::kContinuousActionDim),
      action_(sim::kContinuousActionDim) {
  if (!base_.op || !base_.features) throw core::Error("a residual needs a base actor");
}

void ResidualOperator::Begin(uint64_t seed) {
  if (base_.begin) base_.begin(seed);
  rng_ = core::Rng(seed, 0x5e51);
}

reality::OperatorInput ResidualOperator::Next(const reality::Observation& o) {
  reality::OperatorInput in = base_.op->Next(o);
  if (in.kind != reality::OperatorInput::Kind::kAction) return in;
  base_.features(obs_.data());
  learn::ToUnitAction(in.action, limits_, client_.gripper(), proposal_.data());
  agent_.Act(obs_.data(), proposal_.data(), explore_, rng_, action_.data());
  // No correction sends the base's own action, bit for bit (a continuous one would otherwise come
  // back through a float unit vector a rounding away).
  if (action_ != proposal_) in.action = learn::FromUnitAction(action_.data(), limits_);
  if (on_decision) on_decision({obs_.data(), proposal_.data(), action_.data()});
  return in;
}

}  // namespace twinforge::pipeline
