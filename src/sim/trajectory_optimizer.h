// Trajectory optimization through the simulator: iLQR (Li and Todorov 2004) on MuJoCo's
// finite-differenced transition derivatives (mjd_transitionFD), for SAM-RL's actor, which imitates
// trajectories optimized in the differentiable twin.
//
// The state is MuJoCo's tangent-space state (2 nv + na: positions as velocities, velocities,
// actuator activations), the control the model's `ctrl` (clamped to its ranges). A cost is one
// small class, in the manner of MuJoCo MPC's residuals: it returns its value and a quadratic model
// (Gauss-Newton) around the current state and control.
#pragma once

#include <mujoco/mujoco.h>

#include <Eigen/Dense>
#include <vector>

namespace twinforge::sim {

// A cost's local quadratic model: value + lx'dx + lu'du + dx'lxx dx / 2 + du'luu du / 2.
struct CostModel {
  double value = 0;
  Eigen::VectorXd lx, lu;
  Eigen::MatrixXd lxx, luu;
};

class TrajectoryCost {
 public:
  virtual ~TrajectoryCost() = default;
  // Cost of control `u` applied at step t in state `d` (positions computed; mj_forward has run).
  // Fills `model` when not null (its blocks are sized and zeroed by the caller).
  virtual double Running(const mjModel* m, const mjData* d, const double* u, int t,
                         CostModel* model) const = 0;
  // Cost of the final state.
  virtual double Terminal(const mjModel* m, const mjData* d, CostModel* model) const = 0;
};

// Bring a site to a goal position (world frame): running weight * |p - goal|^2 + control * |u -
// control_ref|^2 + motion * |qvel|^2 at every step, terminal weight * |p - goal|^2 + velocity *
// |qvel|^2 at the end. With running 0 and some motion, the site gets there by the least motion
// spread over the horizon, rather than as fast as the actuators allow.
class SiteReachCost : public TrajectoryCost {
 public:
  SiteReachCost(int site, const Eigen::Vector3d& goal) : site_(site), goal_(goal) {}
  double running = 1.0, terminal = 100.0, control = 1e-3, velocity = 1.0, motion = 0.0;
  Eigen::VectorXd control_ref;  // empty: zero
  // Also turn a site (the same one, or the tool while the reached site is on what it holds) to
  // `goal` (world frame): `weight` * angle^2 (rad^2) added to each position term, at its scale.
  void Turn(int site, const Eigen::Quaterniond& goal, double weight) {
    turn_site_ = site;
    turn_goal_ = goal.normalized();
    turn_weight_ = weight;
  }

  double Running(const mjModel* m, const mjData* d, const double* u, int t,
                 CostModel* model) const override;
  double Terminal(const mjModel* m, const mjData* d, CostModel* model) const override;
  // Distance of the site from the goal in state `d`; angle of the turned site from its goal.
  double Distance(const mjData* d) const;
  double Angle(const mjData* d) const;

 private:
  double SiteTerm(const mjModel* m, const mjData* d, double weight, CostModel* model) const;
  int site_;
  Eigen::Vector3d goal_;
  int turn_site_ = -1;
  Eigen::Quaterniond turn_goal_ = Eigen::Quaterniond::Identity();
  double turn_weight_ = 0;
};

struct IlqrOptions {
  int iterations = 30;
  double fd_epsilon = 1e-6;
  bool fd_centered = false;
  double regularization = 1e-6;  // initial Levenberg-Marquardt term on Quu; grows on failure
  double max_regularization = 1e10;
  double tolerance = 1e-6;  // stop when the relative improvement falls below this
  // A step is taken when it lowers the cost by at least this share of the decrease the
  // quadratic model predicts for it (Armijo).
  double min_reduction_ratio = 1e-4;
  // The dynamics are linearized (mjd_transitionFD, 2 nv + na + nu steps each) at every this-many
  // steps and held between: what costs most, for a horizon of many short physics steps under
  // controls that change slowly (a servo's targets, one per control period). The line search
  // still rolls the true dynamics out, so a step is taken only when it really lowers the cost.
  int linearize_every = 1;
};

struct IlqrResult {
  std::vector<double> controls;  // horizon x nu, row per step
  std::vector<double> costs;     // the initial rollout's cost, then after each iteration
  int iterations = 0;
  bool converged = false;  // the last step improved the cost by less than the tolerance
  bool stalled = false;    // no step lowered the cost enough at any regularization
};

// Optimizes `horizon` controls (`initial` holds horizon x nu, or is empty for the model's
// current ctrl held) from the state in `start` (qpos, qvel, act, time; it is not modified).
// Throws core::NumericError when the rollout diverges from the start.
IlqrResult OptimizeTrajectory(const mjModel* m, const mjData* start, const TrajectoryCost& cost,
                              int horizon, std::vector<double> initial,
                              const IlqrOptions& options = {});

// Cost of applying `controls` from `start`: the rollout iLQR evaluates. Throws
// core::NumericError when the rollout diverges.
double TrajectoryCostOf(const mjModel* m, const mjData* start, const TrajectoryCost& cost,
                        const std::vector<double>& controls);

}  // namespace twinforge::sim
