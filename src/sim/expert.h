// The scripted expert of a task: follows the waypoint list in the task file using privileged
// state, emitting the task's own action type (discrete moves or continuous deltas).
#pragma once

#include <functional>
#include <memory>
#include <vector>

#include "core/rng.h"
#include "sim/env.h"

namespace twinforge::sim {

// How an expert plans its free moves (ScriptedExpert::set_planning).
struct PlanOptions {
  int iterations = 0;    // iLQR iterations a move; 0: every move as scripted
  double stretch = 1.5;  // the plan's length over the control steps the move needs (>= 1)
  // How the expert follows a plan. By the clock (false): it aims at the plan's pose for the
  // control step it is in. Along the path (true): at the plan's pose one step past the one
  // nearest the tool, so where the tool is, not how long the move has taken, decides the aim.
  bool along_path = false;
  // The weight on the arm's joint speeds (squared, rad/s) at the plan's end: 1 brings it to a
  // stop there; 0 lets it arrive moving, as the script's moves do.
  double end_speed_weight = 1.0;
};

// Free moves an expert planned by trajectory optimization, and of them the plans that failed.
struct PlanCounts {
  int planned_moves = 0, failed_plans = 0;
  PlanCounts& operator+=(const PlanCounts& other) {
    planned_moves += other.planned_moves;
    failed_plans += other.failed_plans;
    return *this;
  }
};

class ScriptedExpert {
 public:
  // `noise`: probability of a random move (discrete) or relative std-dev of Gaussian noise on
  // the motion (continuous). Gripper commands are never randomised.
  explicit ScriptedExpert(const Task& task, double noise = 0.0);

  // Starts the script from its first step.
  void Reset();
  // A patient expert never gives a step up (max_steps does not apply): teaching a learner (its
  // actions perturbed, learn/imitate.h), it keeps asking for what the step needs however long the
  // noise keeps it from getting there, and for the gripper as the script last commanded it, not
  // as the gripper is.
  void set_patient(bool patient) { patient_ = patient; }
  // Plans each free move of a continuous task (a move step with no speed limit and no hole
  // search) by trajectory optimization through the env's own model, SAM-RL's optimized teacher:
  // `iterations` of iLQR on MuJoCo's finite-differenced derivatives (sim/trajectory_optimizer.h)
  // bring the moved site (the carried one, or the tool) to the step's target and turn the tool to
  // its orientation, with the least joint motion over `stretch` times the control steps the move
  // needs at the action limits. The expert then aims at the plan's tool poses in turn (by the
  // clock or along the path: PlanOptions), and finishes the move as scripted. 0 iterations (the
  // default): every move as scripted. Throws core::Error for negative iterations, a stretch
  // under 1 or a negative end speed weight.
  void set_planning(const PlanOptions& plan);
  // Whether the hand is clear of what is around it at a tool pose (robot base frame).
  using Clearance = std::function<bool(const core::Pose& tool)>;
  // A move step whose fingers may take any of several directions that serve alike (symmetry)
  // takes the one nearest the tool's when the step starts. With a clearance, the first step of a
  // chain (steps that continue one another: Continues) takes the nearest of those whose tool pose
  // is clear at the target of every step of the chain (the nearest if none is), and the steps
  // after it keep it: the hand is nearly 20 cm along its fingers, and over a block 12 cm from a
  // screen it met the screen; checked at each step's own target, the hand turned a quarter turn
  // with the peg 6 mm over the hole, on its way down, and the tip came down beside it.
  void set_clearance(Clearance clearance) { clearance_ = std::move(clearance); }
  // Moves planned so far, and of them those whose optimization failed (moved as scripted).
  const PlanCounts& plans() const { return plans_; }
  // Goes back to the start of step `step` (a step done again: the scene changed under it).
  // Throws core::Error for a step the script does not have.
  void Restart(int step);
  // The next action for the env's current state.
  Action Act(const Env& env, core::Rng& rng);
  // Whether every step of the script has been done.
  bool finished() const { return step_ >= static_cast<int>(task_.spec().expert.steps.size()); }
  int current_step() const { return step_; }
  // Whether the current step is searching for a hole: its carried site was blocked on the way
  // down (a peg standing beside the hole), and the target walks the step's spiral.
  bool searching() const { return spiral_ > 0; }

 private:
  // Pose the tool should reach for the current step, in the robot base frame.
  core::Pose Target(const Env& env, const ExpertStep& step);
  // Whether step j continues step j - 1: both moves whose fingers may take the same directions
  // alike, in the frame of the same body, carrying the same site (a chain keeps one direction).
  bool Continues(int j) const;
  // Whether the hand, its fingers in direction k, is clear at the target of the current step and
  // of each step after it that continues it.
  bool ChainClear(const Env& env, int k) const;
  // The action that brings the tool toward `target`; for discrete actions sets
  // at_grid_target_ when no move helps.
  Action Toward(const Env& env, const core::Pose& target, double closure);
  Action HoldStill(const Env& env) const;
  // Whether set_planning applies to `step`; the tool pose where the move to `target` starts,
  // then the planned tool poses, one per control step (empty when the optimization failed).
  bool Plans(const ExpertStep& step) const;
  std::vector<core::Pose> PlanMove(const Env& env, const ExpertStep& step,
                                   const core::Pose& target);
  // The index of the pose in plan_ nearest `tool` (0 for an empty plan).
  int NearestPlanPose(const core::Pose& tool) const;
  void Advance();
  void BeginStep(int step);  // the step's own state cleared

  const Task& task_;
  double noise_;
  int step_ = 0;
  int steps_in_step_ = 0;
  bool patient_ = false;
  core::Pose grasp_in_site_;     // drive steps: tool pose relative to the site at the step start
  int finger_turn_ = 0;          // move steps: which of the step's finger directions to use
  double drive_sign_ = 1.0;      // drive steps: direction of travel of the joint
  bool at_grid_target_ = false;  // discrete: no move brings the tool closer to the target
  int last_move_ = -1;           // discrete: the previous motion of this step
  core::Pose frozen_anchor_;     // steps anchored where they start (see freeze_anchor)
  core::Quat kept_rotation_;     // keep_orientation steps: the tool orientation at the start
  // search steps: the carried site's height at the last step, the steps in a row it did not go
  // down, and how far along the spiral the target is (0: not searching).
  double last_height_ = 0;
  int stalled_ = 0;
  int spiral_ = 0;
  PlanOptions planning_;
  PlanCounts plans_;
  Clearance clearance_;
  // The current move's tool poses: where the tool was when the move was planned, then the
  // plan's, one per control step.
  std::vector<core::Pose> plan_;
};

// `action` with noise: a random move with probability `noise` (discrete), or Gaussian noise of
// `noise` times the per-step limit on each motion component (continuous). The gripper's command
// is kept. The expert's own noise, and the noise injected into its actions to teach a learner.
Action PerturbAction(Action action, const ActionLimits& limits, double noise, core::Rng& rng);

// The continuous action that brings `tool` toward `target` (robot base frame): the move and the
// turn in the tool's frame, each component clipped to the step limits (the move to `speed` m if
// that is positive and less), with the gripper asked to `closure` (1: closed).
Action ContinuousToward(const core::Pose& tool, const core::Pose& target,
                        const ActionLimits& limits, double speed, double closure);

// Discrete actions, at the limit of the move grid: the first move of the best short sequence
// (turns and moves) toward `goal`, given in the tool frame; -1 when staying put is best.
int RefiningMove(const core::Pose& goal, const ActionLimits& limits);

}  // namespace twinforge::sim

namespace twinforge::sim {

struct ExpertReport {
  int episodes = 0;
  int successes = 0;
  double success_rate() const { return episodes ? double(successes) / episodes : 0.0; }
  double mean_steps_to_success = 0;  // over successful episodes
  std::vector<int> failed_seeds;     // episode seeds that failed, to replay them
  PlanCounts plans;                  // with planning (ScriptedExpert::set_planning)
};

// Starts episode `episode` of a run seeded `seed` at `level`: resets env and expert and returns
// the generator of the expert's noise. Every tool that names an episode by (seed, index) starts
// it here, so `sim trace --episode i` replays episode i of `sim expert`.
core::Rng BeginExpertEpisode(Env& env, ScriptedExpert& expert, uint64_t seed, int64_t episode,
                             int level);

// Runs the expert for `episodes` episodes at `level` (episode i begun by BeginExpertEpisode),
// spread over `threads` threads with one env per thread. An episode succeeds when the success
// predicates hold at any step; it ends there.
// `plan`: how the expert plans its free moves (ScriptedExpert::set_planning).
ExpertReport EvaluateExpert(std::shared_ptr<const Task> task, int episodes, int level,
                            uint64_t seed, double noise, int threads, const PlanOptions& plan = {});

}  // namespace twinforge::sim
