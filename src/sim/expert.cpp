#include "sim/expert.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numbers>
#include <vector>

#include "core/error.h"
#include "core/log.h"
#include "core/thread_pool.h"
#include "sim/model.h"
#include "sim/trajectory_optimizer.h"

namespace twinforge::sim {

namespace {

// Metres a radian of the tool's turn counts as: a step's turn weighs as much as a step's move, as
// the script counts them.
double TurnWeight(const ActionLimits& limits) { return limits.translation / limits.rotation; }

// Tool orientation with z along `approach` and y along `fingers` (made orthogonal to it).
core::Quat ToolOrientation(const Eigen::Vector3d& approach, const Eigen::Vector3d& fingers) {
  const Eigen::Vector3d z = approach.normalized();
  const Eigen::Vector3d y = (fingers - fingers.dot(z) * z).normalized();
  Eigen::Matrix3d r;
  r << y.cross(z), y, z;
  return core::Quat(r).normalized();
}

// A frame at `pose` keeping only its heading: z up, x along pose's x projected on the table.
core::Pose YawFrame(const core::Pose& pose) {
  const Eigen::Matrix3d r = pose.rotation.toRotationMatrix();
  return {pose.translation, core::Yaw(std::atan2(r(1, 0), r(0, 0)))};
}

// A greedy descent on the move grid stops up to half a step (1.5 cm) from its goal. Turns
// shift the grid: turn, move, turn back and move back lands 6 mm sideways. So a refining step
// searches every sequence of up to kRefineDepth moves and takes the first move of the one that
// ends nearest the goal, each move costing kMoveCost (squared step units) so that a detour is
// taken only for a real gain.
constexpr int kRefineDepth = 4;
constexpr double kMoveCost = 0.005;

struct MoveSearch {
  std::array<core::Pose, 12> moves;
  core::Pose goal;  // in the frame of the start pose
  double translation_step, rotation_step;

  double Error(const core::Pose& p) const {
    const Eigen::Vector3d t = (goal.translation - p.translation) / translation_step;
    const double angle = core::AngleBetween(goal.rotation, p.rotation) / rotation_step;
    return t.squaredNorm() + angle * angle;
  }
  // Least cost over sequences of at most `left` moves from `p` that never undo their last move.
  double Best(const core::Pose& p, int left, int previous) const {
    double best = Error(p);
    if (left == 0) return best;
    for (int move = 0; move < 12; ++move)
      if ((move ^ 1) != previous)
        best = std::min(best, kMoveCost + Best(p * moves[move], left - 1, move));
    return best;
  }
};

// A hole search (ExpertStep::search): an Archimedean spiral of kSpiralPitch between turns (less
// than the 3 mm a peg with 1.5 mm clearance a side drops in from), walked kSpiralArc a step,
// pressing down no more than kSearchPress below the carried site (pressed harder, friction holds
// the peg where it stands, and it tips in the fingers). The site is blocked once it went down
// less than kStallDrop in each of kStallSteps steps.
constexpr double kSpiralPitch = 0.002, kSpiralArc = 0.0015, kSearchPress = 0.0015;
constexpr double kStallDrop = 0.001;
constexpr int kStallSteps = 2;

// The n-th point (n >= 1) of the spiral in its plane, from its middle; past `radius` it starts
// again from the middle.
Eigen::Vector3d SpiralPoint(int n, double radius) {
  const double b = kSpiralPitch / (2 * std::numbers::pi);  // r = b theta
  const int points = std::max(1, int(radius * radius / (2 * kSpiralArc * b)));
  n = (n - 1) % points + 1;
  const double theta = std::sqrt(2 * n * kSpiralArc / b);  // arc length b theta^2 / 2
  return {b * theta * std::cos(theta), b * theta * std::sin(theta), 0.0};
}

// Where the tool goes for a carried site (-1: none, the tool itself) to land on `point`, turned
// `rotation`, holding what it holds as it does now.
Eigen::Vector3d ToolFor(const Env& env, int carry, const Eigen::Vector3d& point,
                        const core::Quat& rotation) {
  if (carry < 0) return point;
  const core::Pose ee = env.EePose();
  const Eigen::Vector3d site_in_tool =
      ee.rotation.conjugate() * (env.SitePose(carry).translation - ee.translation);
  return point - rotation * site_in_tool;
}

// A parallel gripper is symmetric, and so may be what it holds or aligns (a square peg): a move
// step's finger directions that serve alike, in `frame`. They come in opposite pairs: direction
// k is the (k / 2)-th turn of the fingers, reversed when k is odd.
core::Quat FingerDirection(const ExpertStep& step, const core::Quat& frame, int k) {
  const Eigen::Vector3d approach = frame * Eigen::Vector3d(step.approach.data());
  const Eigen::Vector3d fingers = frame * Eigen::Vector3d(step.fingers.data());
  const Eigen::Vector3d turned =
      core::AxisAngle(approach, 2 * M_PI * (k / 2) / step.symmetry) * fingers;
  return ToolOrientation(approach, k % 2 == 0 ? turned : Eigen::Vector3d(-turned));
}

}  // namespace

int RefiningMove(const core::Pose& goal, const ActionLimits& limits) {
  MoveSearch search{{}, goal, limits.translation, limits.rotation};
  for (int move = 0; move < 12; ++move)
    search.moves[move] = DecodeAction(Action::Discrete(move), limits, GripperState{}).delta;
  double best_cost = search.Error(core::Pose::Identity()) - 1e-9;
  int best = -1;
  for (int move = 0; move < 12; ++move) {
    const double cost = kMoveCost + search.Best(search.moves[move], kRefineDepth - 1, move);
    if (cost < best_cost) best_cost = cost, best = move;
  }
  return best;
}

ScriptedExpert::ScriptedExpert(const Task& task, double noise) : task_(task), noise_(noise) {}

void ScriptedExpert::Reset() { BeginStep(0); }

void ScriptedExpert::set_planning(const PlanOptions& plan) {
  if (plan.iterations < 0 || !(plan.stretch >= 1) || !(plan.end_speed_weight >= 0))
    throw core::Error(
        "expert planning: expected iterations >= 0, a stretch >= 1 and an end speed weight >= 0, "
        "got " +
        std::to_string(plan.iterations) + ", " + std::to_string(plan.stretch) + " and " +
        std::to_string(plan.end_speed_weight));
  planning_ = plan;
}

void ScriptedExpert::Restart(int step) {
  if (step < 0 || step >= static_cast<int>(task_.spec().expert.steps.size()))
    throw core::Error(task_.spec().name + ": the expert has no step " + std::to_string(step));
  BeginStep(step);
}

void ScriptedExpert::Advance() { BeginStep(step_ + 1); }

void ScriptedExpert::BeginStep(int step) {
  step_ = step;
  steps_in_step_ = 0;
  last_move_ = -1;
  at_grid_target_ = false;
  stalled_ = spiral_ = 0;
  plan_.clear();
}

bool ScriptedExpert::Plans(const ExpertStep& step) const {
  return planning_.iterations > 0 && task_.spec().control.action == ActionMode::kContinuous &&
         step.type == ExpertStepType::kMove && step.speed <= 0 && step.search <= 0;
}

std::vector<core::Pose> ScriptedExpert::PlanMove(const Env& env, const ExpertStep& step,
                                                 const core::Pose& target) {
  const mjModel* m = env.model();
  const ControlSpec& control = task_.spec().control;
  const int tool = task_.index().robot.ee_site;
  const int carry = task_.index().expert_steps[step_].carry;
  const core::Pose ee = env.EePose();
  const double needed =
      std::max((target.translation - ee.translation).norm() / control.limits.translation,
               core::AngleBetween(target.rotation, ee.rotation) / control.limits.rotation);
  const int steps =
      std::clamp(int(std::ceil(planning_.stretch * needed)) + 1, 2, std::max(2, step.max_steps));
  const core::Pose goal = env.base() * target;
  // Holding something, the plan moves what it holds: the carried site to where the target puts
  // it, through the grasp's own contacts.
  Eigen::Vector3d site_goal = goal.translation;
  if (carry >= 0)
    site_goal =
        goal * (ee.rotation.conjugate() * (env.SitePose(carry).translation - ee.translation));
  SiteReachCost cost(carry >= 0 ? carry : tool, site_goal);
  cost.running = 0;
  cost.terminal = 1e4;
  cost.velocity = planning_.end_speed_weight;
  cost.motion = 1e-2;
  cost.control = 1e-6;
  cost.control_ref = Eigen::Map<const Eigen::VectorXd>(env.data()->ctrl, m->nu);
  const double turn = TurnWeight(control.limits);
  cost.Turn(tool, goal.rotation, turn * turn);
  IlqrOptions options;
  options.iterations = planning_.iterations;
  options.linearize_every = control.substeps;  // the targets change once a control period
  ++plans_.planned_moves;
  const int horizon = steps * control.substeps;
  // Started from the arm's joint targets eased (minimum jerk) to the target's inverse kinematics.
  const RobotIndex& robot = task_.index().robot;
  const ArmVector q_goal = env.kinematics().SolveIk(env.ArmPositions(), target);
  std::vector<double> initial;
  initial.reserve(std::size_t(horizon) * m->nu);
  for (int t = 0; t < horizon; ++t) {
    const double x = double(t + 1) / horizon, ease = x * x * x * (10 - 15 * x + 6 * x * x);
    const std::size_t row = initial.size();
    initial.insert(initial.end(), env.data()->ctrl, env.data()->ctrl + m->nu);
    for (int k = 0; k < kArmDof; ++k) {
      double& u = initial[row + robot.arm_actuator[k]];
      u += ease * (q_goal[k] - u);
    }
  }
  IlqrResult result;
  try {
    result = OptimizeTrajectory(m, env.data(), cost, horizon, std::move(initial), options);
  } catch (const core::NumericError& e) {
    ++plans_.failed_plans;
    spdlog::debug("expert: step {} not planned ({}); moving as scripted", step_, e.what());
    return {};
  }
  // The plan's tool pose at the end of each control step.
  DataPtr d = MakeData(m);
  mj_copyData(d.get(), m, env.data());
  const core::Pose to_base = env.base().Inverse();
  std::vector<core::Pose> plan{ee};
  for (int t = 0; t < horizon; ++t) {
    std::copy_n(result.controls.data() + t * m->nu, m->nu, d->ctrl);
    mj_step(m, d.get());
    if ((t + 1) % control.substeps == 0) {
      mj_kinematics(m, d.get());
      plan.push_back(to_base * SiteWorldPose(d.get(), tool));
    }
  }
  spdlog::debug(
      "expert: step {} planned over {} control steps in {} iterations, cost {:.4g} -> "
      "{:.4g}; the plan ends {:.1f} mm and {:.3f} rad from the target",
      step_, steps, result.iterations, result.costs.front(), result.costs.back(),
      1e3 * (plan.back().translation - target.translation).norm(),
      core::AngleBetween(plan.back().rotation, target.rotation));
  return plan;
}

int ScriptedExpert::NearestPlanPose(const core::Pose& tool) const {
  const double turn = TurnWeight(task_.spec().control.limits);
  int nearest = 0;
  double least = std::numeric_limits<double>::infinity();
  for (int k = 0; k < int(plan_.size()); ++k) {
    const double distance = (plan_[k].translation - tool.translation).norm() +
                            turn * core::AngleBetween(plan_[k].rotation, tool.rotation);
    if (distance < least) least = distance, nearest = k;
  }
  return nearest;
}

core::Pose ScriptedExpert::Target(const Env& env, const ExpertStep& step) {
  const auto& ids = task_.index().expert_steps[step_];
  const core::Pose ee = env.EePose();
  const bool first = steps_in_step_ == 0;
  core::Pose anchor = ids.site < 0 ? core::Pose::Identity() : YawFrame(env.SitePose(ids.site));
  // An anchor on the carried object itself ("lift it 16 cm"), or on one the step moves, is
  // taken where the step starts, or the target would run ahead of the tool.
  const mjModel* m = env.model();
  if (step.freeze_anchor ||
      (ids.carry >= 0 && ids.site >= 0 && m->site_bodyid[ids.site] == m->site_bodyid[ids.carry])) {
    if (first) frozen_anchor_ = anchor;
    anchor = frozen_anchor_;
  }
  core::Pose target;
  target.translation = anchor * Eigen::Vector3d(step.offset.data());
  if (step.search > 0) {
    // Blocked (the site stopped going down), the target walks the spiral a point a step; going
    // down again (in the hole), it stays where the site dropped.
    const double height = env.SitePose(ids.carry).translation.z();
    if (!first) {
      stalled_ = last_height_ - height < kStallDrop ? stalled_ + 1 : 0;
      if (spiral_ > 0 ? stalled_ > 0 : stalled_ >= kStallSteps) ++spiral_;
    }
    last_height_ = height;
    if (spiral_ > 0) target.translation += anchor.rotation * SpiralPoint(spiral_, step.search);
  }
  if (step.keep_orientation) {
    if (first) kept_rotation_ = ee.rotation;
    target.rotation = kept_rotation_;
  } else {
    const core::Quat frame = step.world_orientation ? core::Quat::Identity() : anchor.rotation;
    if (first) {
      // Of the finger directions that serve alike, the one nearest the tool when the step
      // starts (ties to the lower k), kept for the whole step. With a clearance, at the first
      // step of a chain, the nearest whose hand is clear at every target of the chain, if any is.
      std::vector<std::pair<double, int>> order;
      for (int k = 0; k < step.symmetry; ++k)
        order.emplace_back(core::AngleBetween(FingerDirection(step, frame, k), ee.rotation), k);
      std::sort(order.begin(), order.end());
      finger_turn_ = order.front().second;
      if (clearance_ && !Continues(step_))
        for (const auto& [angle, k] : order)
          if (ChainClear(env, k)) {
            finger_turn_ = k;
            break;
          }
    }
    target.rotation = FingerDirection(step, frame, finger_turn_);
  }
  target.translation = ToolFor(env, ids.carry, target.translation, target.rotation);
  return target;
}

bool ScriptedExpert::Continues(int j) const {
  const auto& steps = task_.spec().expert.steps;
  if (j <= 0 || j >= int(steps.size())) return false;
  const ExpertStep &a = steps[j - 1], &b = steps[j];
  const auto& ia = task_.index().expert_steps[j - 1];
  const auto& ib = task_.index().expert_steps[j];
  const auto turnable = [](const ExpertStep& s) {
    return s.type == ExpertStepType::kMove && !s.keep_orientation && s.symmetry > 1;
  };
  const mjModel* m = task_.model();
  return turnable(a) && turnable(b) && a.symmetry == b.symmetry && a.fingers == b.fingers &&
         a.approach == b.approach && a.world_orientation == b.world_orientation &&
         ia.carry == ib.carry && ia.site >= 0 && ib.site >= 0 &&
         m->site_bodyid[ia.site] == m->site_bodyid[ib.site];
}

bool ScriptedExpert::ChainClear(const Env& env, int k) const {
  const auto& steps = task_.spec().expert.steps;
  for (int j = step_; j < int(steps.size()) && (j == step_ || Continues(j)); ++j) {
    const ExpertStep& step = steps[j];
    const auto& ids = task_.index().expert_steps[j];
    const core::Pose anchor =
        ids.site < 0 ? core::Pose::Identity() : YawFrame(env.SitePose(ids.site));
    const core::Quat rotation =
        FingerDirection(step, step.world_orientation ? core::Quat::Identity() : anchor.rotation, k);
    const Eigen::Vector3d point = anchor * Eigen::Vector3d(step.offset.data());
    if (!clearance_({ToolFor(env, ids.carry, point, rotation), rotation})) return false;
  }
  return true;
}

Action ScriptedExpert::HoldStill(const Env& env) const {
  if (task_.spec().control.action == ActionMode::kDiscrete)
    return Action::Discrete(env.gripper().closure > 0.5 ? 13 : 12);  // re-issue the gripper state
  Action a = Action::Continuous({});
  a.value[6] = 2.0 * env.gripper().closure - 1.0;
  return a;
}

Action ScriptedExpert::Toward(const Env& env, const core::Pose& target, double closure) {
  const auto& limits = task_.spec().control.limits;
  const core::Pose ee = env.EePose();
  if (task_.spec().control.action == ActionMode::kDiscrete) {
    const Eigen::Matrix3d to_tool = ee.rotation.toRotationMatrix().transpose();
    const Eigen::Vector3d dp = to_tool * (target.translation - ee.translation);
    const Eigen::Vector3d dr = to_tool * core::LogMap(target.rotation * ee.rotation.conjugate());
    // Gripper first; then the move that most reduces the error, measured in steps (a 3 cm move
    // and a 0.2 rad turn count the same). None helping means the target is as close as the
    // move grid allows: the caller moves on.
    if ((closure > 0.5) != (env.gripper().closure > 0.5))
      return Action::Discrete(closure > 0.5 ? 13 : 12);
    const Eigen::Vector3d t = dp / limits.translation, r = dr / limits.rotation;
    const double now = t.squaredNorm() + r.squaredNorm();
    int best = -1;
    double best_error = now - 1e-9;
    for (int move = 0; move < 12; ++move) {
      Eigen::Vector3d t2 = t, r2 = r;
      const double sign = move % 2 == 0 ? 1.0 : -1.0;
      if (move < 6)
        t2[move / 2] -= sign;
      else
        r2[(move - 6) / 2] -= sign;
      const double error = t2.squaredNorm() + r2.squaredNorm();
      if (error < best_error) best_error = error, best = move;
    }
    // Undoing the previous move would only oscillate around the target.
    const bool undo =
        steps_in_step_ > 0 && last_move_ >= 0 && best >= 0 && (best ^ 1) == last_move_;
    if (best < 0 || undo) {
      best = task_.spec().expert.steps[step_].refine ? RefiningMove(ee.Inverse() * target, limits)
                                                     : -1;
      if (best < 0) {
        at_grid_target_ = true;
        return HoldStill(env);
      }
    }
    last_move_ = best;
    return Action::Discrete(best);
  }
  const double speed = task_.spec().expert.steps[step_].speed;
  return ContinuousToward(ee, target, limits, speed, closure);
}

Action ContinuousToward(const core::Pose& tool, const core::Pose& target,
                        const ActionLimits& limits, double speed, double closure) {
  const Eigen::Matrix3d to_tool = tool.rotation.toRotationMatrix().transpose();
  const Eigen::Vector3d dp = to_tool * (target.translation - tool.translation);
  const Eigen::Vector3d dr = to_tool * core::LogMap(target.rotation * tool.rotation.conjugate());
  const double step_length = speed > 0 ? std::min(speed, limits.translation) : limits.translation;
  Action a = Action::Continuous({});
  for (int k = 0; k < 3; ++k) {
    a.value[k] = std::clamp(dp[k], -step_length, step_length);
    a.value[3 + k] = std::clamp(dr[k], -limits.rotation, limits.rotation);
  }
  a.value[6] = 2.0 * closure - 1.0;
  return a;
}

Action ScriptedExpert::Act(const Env& env, core::Rng& rng) {
  const auto& steps = task_.spec().expert.steps;
  while (!finished()) {
    const ExpertStep& step = steps[step_];
    // The step's gripper command, or, on a step that has none, the gripper as it is; a patient
    // expert asks for it as the script last commanded it.
    double closure = env.gripper().closure;
    for (int k = step_; k >= (patient_ ? 0 : step_); --k)
      if (steps[k].gripper != GripCommand::kKeep) {
        closure = steps[k].gripper == GripCommand::kClose ? 1.0 : 0.0;
        break;
      }
    if (steps_in_step_ >= step.max_steps && !patient_) {
      Advance();  // give up on this step; later steps may still recover
      continue;
    }
    Action action;
    if (step.type == ExpertStepType::kGrip) {
      if (steps_in_step_ >= step.hold) {
        Advance();
        continue;
      }
      ++steps_in_step_;
      return task_.spec().control.action == ActionMode::kDiscrete
                 ? Action::Discrete(closure > 0.5 ? 13 : 12)
                 : Toward(env, env.EePose(), closure);
    }
    if (step.type == ExpertStepType::kMove) {
      const core::Pose target = Target(env, step);
      const core::Pose ee = env.EePose();
      const bool gripper_ready = (closure > 0.5) == (env.gripper().closure > 0.5);
      if ((target.translation - ee.translation).norm() < step.tolerance &&
          core::AngleBetween(target.rotation, ee.rotation) < step.rotation_tolerance &&
          gripper_ready) {
        Advance();
        continue;
      }
      at_grid_target_ = false;
      core::Pose aim = target;
      if (Plans(step)) {
        if (steps_in_step_ == 0) plan_ = PlanMove(env, step, target);
        const int next = planning_.along_path ? NearestPlanPose(ee) + 1 : steps_in_step_ + 1;
        if (next < int(plan_.size())) aim = plan_[next];
      }
      if (spiral_ > 0 && stalled_ > 0)  // searching, still blocked: press gently
        aim.translation.z() = std::max(aim.translation.z(), ee.translation.z() - kSearchPress);
      action = Toward(env, aim, closure);
      if (at_grid_target_) {
        Advance();
        continue;
      }
    } else {  // drive a joint by moving the grasped part ahead of the grasp
      const mjModel* m = env.model();
      const mjData* d = env.data();
      const int joint = task_.index().expert_steps[step_].joint;
      const int site = task_.index().expert_steps[step_].site;
      const double value = d->qpos[m->jnt_qposadr[joint]];
      const core::Pose site_pose = env.SitePose(site);
      if (steps_in_step_ == 0) {
        grasp_in_site_ = site_pose.Inverse() * env.EePose();
        drive_sign_ = step.to >= value ? 1.0 : -1.0;
      }
      const double remaining = step.to - value;
      if (remaining * drive_sign_ < 0.005) {  // reached or passed the target
        Advance();
        continue;
      }
      const double lead = std::copysign(std::min(step.lead, std::abs(remaining) + 0.01), remaining);
      const core::Pose to_base = env.base().Inverse();
      const Eigen::Vector3d axis = to_base.rotation * Eigen::Vector3d(d->xaxis + 3 * joint);
      core::Pose ahead;
      if (m->jnt_type[joint] == mjJNT_SLIDE) {
        ahead.translation = axis * lead;
      } else {
        const Eigen::Vector3d anchor = to_base * Eigen::Vector3d(d->xanchor + 3 * joint);
        ahead.rotation = core::AxisAngle(axis, lead);
        ahead.translation = anchor - ahead.rotation * anchor;
      }
      action = Toward(env, ahead * site_pose * grasp_in_site_, closure);
    }
    ++steps_in_step_;
    return noise_ > 0 ? PerturbAction(action, task_.spec().control.limits, noise_, rng) : action;
  }
  return HoldStill(env);
}

Action PerturbAction(Action action, const ActionLimits& limits, double noise, core::Rng& rng) {
  if (action.mode == ActionMode::kDiscrete) {
    if (action.index < 12 && rng.Bernoulli(noise)) action.index = static_cast<int>(rng.Index(12));
    return action;
  }
  for (int k = 0; k < 6; ++k)
    action.value[k] += rng.Normal() * noise * (k < 3 ? limits.translation : limits.rotation);
  return action;
}

core::Rng BeginExpertEpisode(Env& env, ScriptedExpert& expert, uint64_t seed, int64_t episode,
                             int level) {
  const uint64_t episode_seed = core::MixSeed(seed, static_cast<uint64_t>(episode));
  env.Reset(episode_seed, level);
  expert.Reset();
  return core::Rng(episode_seed, 0xe4);
}

ExpertReport EvaluateExpert(std::shared_ptr<const Task> task, int episodes, int level,
                            uint64_t seed, double noise, int threads, const PlanOptions& plan) {
  ExpertReport report;
  report.episodes = episodes;
  std::vector<int> steps_to_success(episodes, -1);
  core::ThreadPool pool(threads);
  std::vector<PlanCounts> plans(pool.size());
  // Each range builds one env; each episode depends only on its seed.
  pool.ParallelRanges(episodes, [&](int block, int64_t begin, int64_t end) {
    Env env(task, block);
    ScriptedExpert expert(*task, noise);
    expert.set_planning(plan);
    for (int64_t i = begin; i < end; ++i) {
      core::Rng rng = BeginExpertEpisode(env, expert, seed, i, level);
      for (int t = 0; t < task->spec().horizon; ++t) {
        const StepResult r = env.Step(expert.Act(env, rng));
        if (r.success) {
          steps_to_success[i] = t + 1;
          break;
        }
        if (r.done) break;
      }
    }
    plans[block] = expert.plans();
  });
  for (const PlanCounts& p : plans) report.plans += p;
  double total = 0;
  for (int i = 0; i < episodes; ++i) {
    if (steps_to_success[i] > 0) {
      ++report.successes;
      total += steps_to_success[i];
    } else {
      report.failed_seeds.push_back(i);
    }
  }
  report.mean_steps_to_success = report.successes ? total / report.successes : 0.0;
  return report;
}

}  // namespace twinforge::sim
