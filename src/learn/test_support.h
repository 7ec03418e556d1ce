// A task small enough for learning tests: in the drawer scene, bring the tool within 14 cm (or
// `within`) of the handle in 20 moves. The untrained policy's sampled moves succeed in a few
// percent of episodes; PPO lifts that to most of them in a few seconds.
#pragma once

#include <memory>

#include "sim/task.h"

namespace twinforge::learn::testing {

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

}  // namespace twinforge::learn::testing
