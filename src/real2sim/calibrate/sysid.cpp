#include "real2sim/calibrate/sysid.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <numeric>
#include <random>

#include "core/error.h"

namespace twinforge::real2sim {
namespace {

int Find(const mjModel* m, mjtObj type, const PhysicalParameter& p) {
  const int id = mj_name2id(m, type, p.name.c_str());
  if (id < 0)
    throw core::ConfigError("sysid", p.name,
                            std::string("a ") + ToString(p.kind) + " named in the model");
  return id;
}

// A search's start and bounds as log-parameters, the start clamped to the bounds.
struct LogSpace {
  std::vector<double> start, lower, upper;
};
LogSpace ToLogSpace(const std::vector<double>& start, const std::vector<double>& lower,
                    const std::vector<double>& upper) {
  const size_t n = start.size();
  if (lower.size() != n || upper.size() != n)
    throw core::ConfigError("sysid", "lower", "one bound of each kind per parameter");
  LogSpace s{std::vector<double>(n), std::vector<double>(n), std::vector<double>(n)};
  for (size_t i = 0; i < n; ++i) {
    s.lower[i] = std::log(lower[i]);
    s.upper[i] = std::log(upper[i]);
    s.start[i] = std::clamp(std::log(std::max(start[i], 1e-12)), s.lower[i], s.upper[i]);
  }
  return s;
}

// A one-point function as a batch of one point at a time.
template <class T>
Batch<T> OneByOne(const std::function<T(const std::vector<double>&)>& f) {
  return [&f](const std::vector<std::vector<double>>& points) {
    std::vector<T> out;
    out.reserve(points.size());
    for (const auto& p : points) out.push_back(f(p));
    return out;
  };
}

}  // namespace

const char* ToString(PhysicalParameter::Kind kind) {
  switch (kind) {
    case PhysicalParameter::Kind::kBodyMass:
      return "body_mass";
    case PhysicalParameter::Kind::kGeomFriction:
      return "geom_friction";
    case PhysicalParameter::Kind::kJointDamping:
      return "joint_damping";
    case PhysicalParameter::Kind::kJointFriction:
      return "joint_friction";
    case PhysicalParameter::Kind::kActuatorGain:
      return "actuator_gain";
    case PhysicalParameter::Kind::kActuatorForce:
      return "actuator_force";
  }
  return "?";
}

double GetParameter(const mjModel* m, const PhysicalParameter& p) {
  using K = PhysicalParameter::Kind;
  switch (p.kind) {
    case K::kBodyMass:
      return m->body_mass[Find(m, mjOBJ_BODY, p)];
    case K::kGeomFriction:
      return m->geom_friction[3 * Find(m, mjOBJ_GEOM, p)];
    case K::kJointDamping:
      return m->dof_damping[m->jnt_dofadr[Find(m, mjOBJ_JOINT, p)]];
    case K::kJointFriction:
      return m->dof_frictionloss[m->jnt_dofadr[Find(m, mjOBJ_JOINT, p)]];
    case K::kActuatorGain:
      return m->actuator_gainprm[mjNGAIN * Find(m, mjOBJ_ACTUATOR, p)];
    case K::kActuatorForce: {
      const int a = Find(m, mjOBJ_ACTUATOR, p);
      return m->actuator_forcelimited[a] ? m->actuator_forcerange[2 * a + 1] : HUGE_VAL;
    }
  }
  return 0;
}

void SetParameter(mjModel* m, const PhysicalParameter& p, double value) {
  using K = PhysicalParameter::Kind;
  switch (p.kind) {
    case K::kBodyMass: {
      const int b = Find(m, mjOBJ_BODY, p);
      const double scale = value / m->body_mass[b];
      m->body_mass[b] = value;
      for (int i = 0; i < 3; ++i) m->body_inertia[3 * b + i] *= scale;
      break;
    }
    case K::kGeomFriction:
      m->geom_friction[3 * Find(m, mjOBJ_GEOM, p)] = value;
      break;
    case K::kJointDamping:
      m->dof_damping[m->jnt_dofadr[Find(m, mjOBJ_JOINT, p)]] = value;
      break;
    case K::kJointFriction:
      m->dof_frictionloss[m->jnt_dofadr[Find(m, mjOBJ_JOINT, p)]] = value;
      break;
    case K::kActuatorGain: {
      // A position actuator: force = kp * ctrl - kp * q - kv * qdot.
      const int a = Find(m, mjOBJ_ACTUATOR, p);
      m->actuator_gainprm[mjNGAIN * a] = value;
      m->actuator_biasprm[mjNBIAS * a + 1] = -value;
      break;
    }
    case K::kActuatorForce: {
      const int a = Find(m, mjOBJ_ACTUATOR, p);
      m->actuator_forcelimited[a] = 1;
      m->actuator_forcerange[2 * a] = -value;
      m->actuator_forcerange[2 * a + 1] = value;
      break;
    }
  }
}

std::vector<std::vector<double>> Replay(const mjModel* m, const Trajectory& t) {
  if (static_cast<int>(t.qpos0.size()) != m->nq || static_cast<int>(t.qvel0.size()) != m->nv)
    throw core::ConfigError("sysid", "qpos0", "a start state of the model's size");
  sim::DataPtr d = sim::MakeData(m);
  std::copy(t.qpos0.begin(), t.qpos0.end(), d->qpos);
  std::copy(t.qvel0.begin(), t.qvel0.end(), d->qvel);
  mj_forward(m, d.get());
  std::vector<std::vector<double>> out;
  for (const auto& ctrl : t.ctrl) {
    std::copy(ctrl.begin(), ctrl.begin() + std::min<size_t>(ctrl.size(), m->nu), d->ctrl);
    for (int s = 0; s < t.substeps; ++s) mj_step(m, d.get());
    std::vector<double> seen;
    for (int i : t.measured) seen.push_back(d->qpos[i]);
    out.push_back(std::move(seen));
  }
  return out;
}

double TrajectoryError(const mjModel* m, const std::vector<Trajectory>& trajectories) {
  double sum = 0;
  int n = 0;
  for (const Trajectory& t : trajectories) {
    const auto replay = Replay(m, t);
    for (size_t k = 0; k < replay.size() && k < t.positions.size(); ++k) {
      for (size_t i = 0; i < replay[k].size(); ++i) {
        const double e = replay[k][i] - t.positions[k][i];
        sum += e * e;
        ++n;
      }
    }
  }
  return n > 0 ? sum / n : 0;
}

SysidResult MinimizeLogSpace(const std::function<double(const std::vector<double>&)>& objective,
                             const std::vector<double>& start, const std::vector<double>& lower,
                             const std::vector<double>& upper, const SysidOptions& options) {
  return BatchMinimizeLogSpace(OneByOne(objective), start, lower, upper, options);
}

SysidResult BatchMinimizeLogSpace(const Batch<double>& objective, const std::vector<double>& start,
                                  const std::vector<double>& lower,
                                  const std::vector<double>& upper, const SysidOptions& options) {
  const size_t n = start.size();
  SysidResult result;
  auto [x, lo, hi] = ToLogSpace(start, lower, upper);
  // The errors at log-parameters `at`, one batch.
  auto errors = [&](const std::vector<std::vector<double>>& at) {
    std::vector<std::vector<double>> values(at.size(), std::vector<double>(n));
    for (size_t k = 0; k < at.size(); ++k)
      for (size_t i = 0; i < n; ++i) values[k][i] = std::exp(at[k][i]);
    result.replays += static_cast<int>(at.size());
    std::vector<double> out = objective(values);
    if (out.size() != at.size())
      throw core::ConfigError("sysid", "objective", "one value per point of a batch");
    return out;
  };
  auto error = [&](const std::vector<double>& at) { return errors({at}).front(); };
  auto clamp = [&](std::vector<double>& at) {
    for (size_t i = 0; i < n; ++i) at[i] = std::clamp(at[i], lo[i], hi[i]);
  };
  std::vector<double> best = x;
  double best_error = error(x);

  if (options.method == SysidOptions::Method::kGradient) {
    // Normalized gradient steps with backtracking: a step that does not lower the error is halved.
    double step = options.step;
    for (int it = 0; it < options.iterations && step > 1e-6; ++it) {
      std::vector<std::vector<double>> steps;  // up and down along each parameter
      for (size_t i = 0; i < n; ++i)
        for (double sign : {1.0, -1.0}) {
          steps.push_back(best);
          steps.back()[i] += sign * options.difference;
        }
      const std::vector<double> sides = errors(steps);
      std::vector<double> g(n);
      for (size_t i = 0; i < n; ++i)
        g[i] = (sides[2 * i] - sides[2 * i + 1]) / (2 * options.difference);
      const double norm = std::sqrt(std::inner_product(g.begin(), g.end(), g.begin(), 0.0));
      if (norm <= 0) break;
      std::vector<double> next = best;
      for (size_t i = 0; i < n; ++i) next[i] -= step * g[i] / norm;
      clamp(next);
      const double e = error(next);
      if (e < best_error) {
        best = next;
        best_error = e;
        step *= 1.2;
      } else {
        step *= 0.5;
      }
      result.error.push_back(best_error);
    }
  } else {
    // Separable CMA-ES: a Gaussian with a diagonal covariance, moved to the best half.
    std::mt19937_64 rng(options.seed);
    std::normal_distribution<double> normal;
    const int lambda = std::max(4, options.population), mu = lambda / 2;
    std::vector<double> weights(mu);
    for (int i = 0; i < mu; ++i) weights[i] = std::log(mu + 0.5) - std::log(i + 1.0);
    const double wsum = std::accumulate(weights.begin(), weights.end(), 0.0);
    for (double& w : weights) w /= wsum;
    std::vector<double> mean = best, scale(n, 1.0);
    double sigma = options.sigma;
    for (int it = 0; it < options.iterations; ++it) {
      std::vector<std::vector<double>> drawn;
      for (int k = 0; k < lambda; ++k) {
        std::vector<double> s(n);
        for (size_t i = 0; i < n; ++i) s[i] = mean[i] + sigma * scale[i] * normal(rng);
        clamp(s);
        drawn.push_back(std::move(s));
      }
      const std::vector<double> e = errors(drawn);
      std::vector<std::pair<double, std::vector<double>>> samples;
      for (int k = 0; k < lambda; ++k) samples.push_back({e[k], std::move(drawn[k])});
      std::sort(samples.begin(), samples.end(),
                [](const auto& a, const auto& b) { return a.first < b.first; });
      if (samples.front().first < best_error) {
        best_error = samples.front().first;
        best = samples.front().second;
      }
      std::vector<double> next(n, 0.0), spread(n, 0.0);
      for (int k = 0; k < mu; ++k)
        for (size_t i = 0; i < n; ++i) next[i] += weights[k] * samples[k].second[i];
      for (int k = 0; k < mu; ++k)
        for (size_t i = 0; i < n; ++i)
          spread[i] += weights[k] * std::pow((samples[k].second[i] - mean[i]) / sigma, 2);
      for (size_t i = 0; i < n; ++i)
        scale[i] = std::sqrt(0.7 * scale[i] * scale[i] + 0.3 * spread[i]);
      // The step shrinks as the best half gathers: the mean moved less than sigma would.
      double moved = 0;
      for (size_t i = 0; i < n; ++i)
        moved += std::pow((next[i] - mean[i]) / (sigma * scale[i] + 1e-12), 2);
      sigma *= std::exp(0.2 * (std::sqrt(moved / n) * std::sqrt(static_cast<double>(mu)) - 1));
      sigma = std::clamp(sigma, 1e-6, 2.0);
      mean = next;
      result.error.push_back(best_error);
    }
  }
  result.values.resize(n);
  for (size_t i = 0; i < n; ++i) result.values[i] = std::exp(best[i]);
  return result;
}

LeastSquaresResult LeastSquaresLogSpace(
    const std::function<Eigen::VectorXd(const std::vector<double>&)>& residuals,
    const std::vector<double>& start, const std::vector<double>& lower,
    const std::vector<double>& upper, const SysidOptions& options) {
  return BatchLeastSquaresLogSpace(OneByOne(residuals), start, lower, upper, options);
}

LeastSquaresResult BatchLeastSquaresLogSpace(const Batch<Eigen::VectorXd>& residuals,
                                             const std::vector<double>& start,
                                             const std::vector<double>& lower,
                                             const std::vector<double>& upper,
                                             const SysidOptions& options) {
  const int n = static_cast<int>(start.size());
  LeastSquaresResult result;
  const auto log_space = ToLogSpace(start, lower, upper);
  auto as_vector = [&](const std::vector<double>& v) {
    return Eigen::VectorXd(Eigen::Map<const Eigen::VectorXd>(v.data(), n));
  };
  Eigen::VectorXd x = as_vector(log_space.start);
  const Eigen::VectorXd lo = as_vector(log_space.lower), hi = as_vector(log_space.upper);
  // The residuals at log-parameters `at`, one batch.
  auto evaluate_all = [&](const std::vector<Eigen::VectorXd>& at) {
    std::vector<std::vector<double>> values(at.size(), std::vector<double>(n));
    for (size_t k = 0; k < at.size(); ++k)
      for (int i = 0; i < n; ++i) values[k][i] = std::exp(at[k][i]);
    result.replays += static_cast<int>(at.size());
    std::vector<Eigen::VectorXd> out = residuals(values);
    if (out.size() != at.size())
      throw core::ConfigError("sysid", "residuals", "one vector per point of a batch");
    return out;
  };
  auto evaluate = [&](const Eigen::VectorXd& at) { return evaluate_all({at}).front(); };
  // Central differences, stepping inward at a bound: up and down along each parameter, one batch.
  auto jacobian = [&](const Eigen::VectorXd& at, long rows) {
    std::vector<Eigen::VectorXd> steps;
    for (int i = 0; i < n; ++i) {
      steps.push_back(at);
      steps.back()[i] = std::min(at[i] + options.difference, hi[i]);
      steps.push_back(at);
      steps.back()[i] = std::max(at[i] - options.difference, lo[i]);
    }
    const std::vector<Eigen::VectorXd> r = evaluate_all(steps);
    Eigen::MatrixXd j(rows, n);
    for (int i = 0; i < n; ++i)
      j.col(i) = (r[2 * i] - r[2 * i + 1]) / std::max(steps[2 * i][i] - steps[2 * i + 1][i], 1e-12);
    return j;
  };
  Eigen::VectorXd r = evaluate(x);
  double cost = r.squaredNorm();
  double lambda = 1e-2;
  Eigen::MatrixXd j = jacobian(x, r.size());
  for (int it = 0; it < options.iterations; ++it) {
    const Eigen::MatrixXd a = j.transpose() * j;
    const Eigen::VectorXd g = j.transpose() * r;
    bool improved = false;
    // Damped Gauss-Newton steps, more damped until one lowers the cost.
    for (int tries = 0; tries < 8 && !improved; ++tries) {
      Eigen::MatrixXd damped = a;
      damped.diagonal() += lambda * (a.diagonal().array() + 1e-12).matrix();
      Eigen::VectorXd next = x + damped.ldlt().solve(-g);
      next = next.cwiseMax(lo).cwiseMin(hi);
      const Eigen::VectorXd rn = evaluate(next);
      if (rn.squaredNorm() < cost) {
        x = next;
        r = rn;
        cost = rn.squaredNorm();
        lambda = std::max(lambda / 3, 1e-7);
        improved = true;
      } else {
        lambda *= 4;
      }
    }
    result.error.push_back(r.size() ? cost / r.size() : 0);
    if (!improved) break;
    j = jacobian(x, r.size());
  }
  const double dof = std::max<double>(1, static_cast<double>(r.size()) - n);
  const Eigen::MatrixXd covariance =
      cost / dof * (j.transpose() * j).completeOrthogonalDecomposition().pseudoInverse();
  for (int i = 0; i < n; ++i) {
    result.values.push_back(std::exp(x[i]));
    const double c = covariance(i, i);
    result.relative_error.push_back(j.col(i).squaredNorm() > 0 && std::isfinite(c) ? std::sqrt(c)
                                                                                   : HUGE_VAL);
  }
  return result;
}

SysidResult IdentifyParameters(mjModel* m, const std::vector<PhysicalParameter>& parameters,
                               const std::vector<Trajectory>& trajectories,
                               const SysidOptions& options) {
  std::vector<double> start, lower, upper;
  for (const auto& p : parameters) {
    start.push_back(GetParameter(m, p));
    lower.push_back(p.lower);
    upper.push_back(p.upper);
  }
  auto set = [&](const std::vector<double>& values) {
    for (size_t i = 0; i < parameters.size(); ++i) SetParameter(m, parameters[i], values[i]);
  };
  SysidResult result = MinimizeLogSpace(
      [&](const std::vector<double>& values) {
        set(values);
        return TrajectoryError(m, trajectories);
      },
      start, lower, upper, options);
  set(result.values);
  return result;
}

}  // namespace twinforge::real2sim
