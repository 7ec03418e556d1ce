// SAM-RL's twin actor as the commands set it up (eval --actor twin, train residual --actor twin):
// its options, and the actor on a robot with everything it looks with.
//
// Includes <torch/torch.h> (via pipeline/residual_operator.h): include it from app's .cpp only.
#pragma once

#include <CLI/CLI.hpp>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>

#include "pipeline/residual_operator.h"
#include "pipeline/sensing_q_training.h"
#include "real2sim/calibrate/twin_geometry.h"
#include "samrl/twin_actor.h"
#include "sim/task.h"

namespace twinforge::app {

struct TwinActorCli {
  std::string actor = "policy";  // what acts: a --policy file, or the twin actor
  std::string look = "active", register_to = "robot-and-table";
  double register_min_hold = samrl::PoseEstimateOptions{}.register_min_hold;
  std::string q;             // --look q: the sensing-aware Q (train samrl's q.pt)
  std::string actor_policy;  // the twin actor acts with this state policy (train imitate's)
  int capture_scale = 8;
  double settle = samrl::PoseEstimateOptions{}.settle;            // m: each fit settled (0: not)
  double turn_margin = samrl::PoseEstimateOptions{}.turn_margin;  // of the fit's points (0: not)
  samrl::RelookOptions relook;
  CLI::Option *measure_held = nullptr, *refine = nullptr;  // given on the command line or not

  // `relook` as the actor takes it: --measure-held and --refine, unless given, on where the look
  // chooses its view around the arm (active, q) and off for a fixed view. Seen by a fixed camera
  // from the front, the arm over the block hid it at the look from over the hole, and a refined
  // fit there was worse than the one it replaced (peg_insertion, level 3: 0.5 -> 2.2 mm).
  samrl::RelookOptions Relook() const;

  // --actor, --actor-policy, --look, --q, --register-to, --register-min-hold, --capture-scale,
  // --settle, --turn-margin, --max-looks, --moved, --look-when-blocked, --moved-when-blocked,
  // --look-when-unseen, --measure-held, --refine, --occluders, --max-move.
  void Add(CLI::App* command);
  // Throws when the options disagree, with each other or with `policy` (the --policy file:
  // needed by --actor policy, refused by --actor twin; --q goes with --look q); `command` names
  // who asked.
  void Check(const std::string& command, const std::string& policy) const;
  bool twin() const { return actor == "twin"; }
};

// The twin actor at `robot`'s controls, on the twin `task`. It says "done" when the robot's
// oracle (if it has one) reports success. `seed` makes the view search repeatable.
class TwinActorOnRobot {
 public:
  TwinActorOnRobot(reality::Robot& robot, const sim::TaskSpec& task, const TwinActorCli& cli,
                   uint64_t seed);

  samrl::TwinActor& actor() { return *actor_; }
  // The actor as a residual's base: the twin (by content) is its identity.
  pipeline::ResidualBase AsResidualBase();
  // The identity and the looking protocol, for a trial log's header.
  nlohmann::json header() const;

 private:
  std::shared_ptr<const sim::Task> twin_;
  std::unique_ptr<real2sim::TwinGeometry> geometry_;
  pipeline::SensingQModel q_;
  samrl::Look look_;
  std::unique_ptr<samrl::TwinActor> actor_;
  nlohmann::json identity_, header_;
};

}  // namespace twinforge::app
