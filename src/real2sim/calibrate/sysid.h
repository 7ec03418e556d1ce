// System identification: the physical parameters of a twin (masses, frictions, joint damping,
// actuator gains) that make its motion match recorded real trajectories.
//
// A trajectory is a start state, the controls applied at each control step and what was measured
// after it (some of the model's positions). The twin replays the controls from the same start and
// the error is the mean squared difference of the measured positions. Parameters are searched in
// log space (they are positive and their scales differ): by gradient descent with gradients from
// central finite differences through MuJoCo (one replay per perturbed parameter), or by CMA-ES
// (diagonal covariance) when the error is too rough for gradients.
#pragma once

#include <Eigen/Dense>
#include <functional>
#include <string>
#include <vector>

#include "sim/model.h"

namespace twinforge::real2sim {

// One physical parameter of a model, named as in the MJCF.
struct PhysicalParameter {
  enum class Kind {
    kBodyMass,       // body `name`'s mass (its inertia scaled along)
    kGeomFriction,   // geom `name`'s sliding friction
    kJointDamping,   // joint `name`'s damping
    kJointFriction,  // joint `name`'s dry friction (frictionloss)
    kActuatorGain,   // position actuator `name`'s stiffness kp (gain and bias together)
    kActuatorForce,  // actuator `name`'s force limit (symmetric; a gripper's grip force)
  } kind = Kind::kGeomFriction;
  std::string name;
  double lower = 1e-4, upper = 1e4;  // the search stays within
};
const char* ToString(PhysicalParameter::Kind kind);

// Reads / writes a parameter in `m`. Throws ConfigError if `name` is not in the model.
double GetParameter(const mjModel* m, const PhysicalParameter& p);
void SetParameter(mjModel* m, const PhysicalParameter& p, double value);

struct Trajectory {
  std::vector<double> qpos0, qvel0;            // start state (nq, nv)
  int substeps = 1;                            // physics steps per control step
  std::vector<std::vector<double>> ctrl;       // per control step (nu)
  std::vector<int> measured;                   // qpos indices measured
  std::vector<std::vector<double>> positions;  // per control step, after it (measured.size())
};

// Replays `t` in `m` (from its start state) and returns the measured positions per step.
std::vector<std::vector<double>> Replay(const mjModel* m, const Trajectory& t);
// Mean squared difference between the replay and the measured positions, over all trajectories.
double TrajectoryError(const mjModel* m, const std::vector<Trajectory>& trajectories);

struct SysidOptions {
  enum class Method { kGradient, kCmaEs } method = Method::kGradient;
  int iterations = 60;
  double step = 0.2;         // gradient: largest change of a log-parameter per iteration
  double difference = 0.03;  // gradient: central-difference step in log space (contacts make
                             // the error rough at finer scales)
  int population = 10;       // CMA-ES: samples per generation
  double sigma = 0.5;        // CMA-ES: initial spread in log space
  unsigned seed = 1;
};

struct SysidResult {
  std::vector<double> values;  // identified, in the order of the parameters
  std::vector<double> error;   // trajectory error per iteration (the best so far)
  int replays = 0;             // trajectory replays spent
};

// An objective (or residuals) evaluated at several points at once, so that the caller can spread
// them over threads: the result at each point must depend on that point only.
template <class T>
using Batch = std::function<std::vector<T>(const std::vector<std::vector<double>>&)>;

// Minimizes `objective` over positive values, searched in log space within [lower, upper] from
// `start`, by the method of `options`. Returns the best values found and the error history.
SysidResult MinimizeLogSpace(const std::function<double(const std::vector<double>&)>& objective,
                             const std::vector<double>& start, const std::vector<double>& lower,
                             const std::vector<double>& upper, const SysidOptions& options = {});
// As above, evaluating a gradient's differences or a CMA-ES generation as one batch. The search is
// the same: the points are drawn and evaluated in the same order.
SysidResult BatchMinimizeLogSpace(const Batch<double>& objective, const std::vector<double>& start,
                                  const std::vector<double>& lower,
                                  const std::vector<double>& upper,
                                  const SysidOptions& options = {});

// Least squares over positive values in log space: Levenberg-Marquardt on `residuals` with the
// Jacobian by central differences (`options.difference`), `options.iterations` at most. Also
// returns each value's relative standard error, sigma^2 (J^T J)^-1 at the optimum (infinite
// where the residuals do not pin it down).
struct LeastSquaresResult : SysidResult {
  std::vector<double> relative_error;
};
LeastSquaresResult LeastSquaresLogSpace(
    const std::function<Eigen::VectorXd(const std::vector<double>&)>& residuals,
    const std::vector<double>& start, const std::vector<double>& lower,
    const std::vector<double>& upper, const SysidOptions& options = {});
// As above, evaluating each Jacobian's central differences as one batch.
LeastSquaresResult BatchLeastSquaresLogSpace(const Batch<Eigen::VectorXd>& residuals,
                                             const std::vector<double>& start,
                                             const std::vector<double>& lower,
                                             const std::vector<double>& upper,
                                             const SysidOptions& options = {});

// Identifies `parameters` of `m` (their current values are the start) from `trajectories`.
// `m` is left with the identified values.
SysidResult IdentifyParameters(mjModel* m, const std::vector<PhysicalParameter>& parameters,
                               const std::vector<Trajectory>& trajectories,
                               const SysidOptions& options = {});

}  // namespace twinforge::real2sim
