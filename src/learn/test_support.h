// Learning tests' fixtures: a tiny task and a state policy's shape for it.
#pragma once

#include <memory>

#include "learn/policy_net.h"
#include "sim/env.h"
#include "sim/task.h"

namespace twinforge::learn::testing {

// A task small enough for learning tests: in the drawer scene, bring the tool within 14 cm (or
// `within`) of the handle in 20 moves. The untrained policy's sampled moves succeed in a few
// percent of episodes; PPO lifts that to most of them in a few seconds.
inline std::shared_ptr<const sim::Task> ReachTask(double within = 0.14) {
  sim::TaskSpec spec = sim::LoadTaskSpec("open_drawer");
  spec.name = "reach_handle";
  spec.horizon = 20;
  sim::SuccessPredicate near;
  near.type = sim::PredicateType::kSiteDistanceBelow;
  near.site_a = "ee";
  near.site_b = "drawer_handle";
  near.threshold = within;
  spec.success = {near};
  return std::make_shared<const sim::Task>(std::move(spec));
}

// A state policy's config for `task`: the privileged state in, no points.
inline PolicyConfig StatePolicyConfig(const sim::Task& task) {
  PolicyConfig config;
  config.point_features = 0;
  config.proprio_dim = sim::StateDim(task);
  return config;
}

}  // namespace twinforge::learn::testing
