#include "sim/trajectory_optimizer.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "core/error.h"
#include "sim/model.h"

namespace twinforge::sim {

namespace {

using RowMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

int StateDim(const mjModel* m) { return 2 * m->nv + m->na; }

CostModel ZeroModel(const mjModel* m) {
  const int n = StateDim(m), nu = m->nu;
  return {0, Eigen::VectorXd::Zero(n), Eigen::VectorXd::Zero(nu), Eigen::MatrixXd::Zero(n, n),
          Eigen::MatrixXd::Zero(nu, nu)};
}

// The simulator state at each step of a rollout.
struct Trajectory {
  std::vector<double> qpos, qvel, act, warmstart, time;
  std::vector<double> controls;
  double cost = 0;
};

void StoreState(const mjModel* m, const mjData* d, int t, Trajectory& tr) {
  std::copy_n(d->qpos, m->nq, tr.qpos.data() + t * m->nq);
  std::copy_n(d->qvel, m->nv, tr.qvel.data() + t * m->nv);
  std::copy_n(d->act, m->na, tr.act.data() + t * m->na);
  std::copy_n(d->qacc_warmstart, m->nv, tr.warmstart.data() + t * m->nv);
  tr.time[t] = d->time;
}

void LoadState(const mjModel* m, const Trajectory& tr, int t, mjData* d) {
  std::copy_n(tr.qpos.data() + t * m->nq, m->nq, d->qpos);
  std::copy_n(tr.qvel.data() + t * m->nv, m->nv, d->qvel);
  std::copy_n(tr.act.data() + t * m->na, m->na, d->act);
  std::copy_n(tr.warmstart.data() + t * m->nv, m->nv, d->qacc_warmstart);
  d->time = tr.time[t];
}

void ClampControls(const mjModel* m, double* u) {
  for (int i = 0; i < m->nu; ++i)
    if (m->actuator_ctrllimited[i])
      u[i] = std::clamp(u[i], m->actuator_ctrlrange[2 * i], m->actuator_ctrlrange[2 * i + 1]);
}

bool Finite(const double* v, int n) {
  for (int i = 0; i < n; ++i)
    if (!std::isfinite(v[i])) return false;
  return true;
}

// Rolls `controls` (clamped in place) out from `start`, or with a nominal trajectory and
// gains, u = clamp(u_nom + alpha k + K dx). Returns false if the state went non-finite.
struct Feedback {
  const Trajectory* nominal = nullptr;
  const std::vector<Eigen::VectorXd>* k = nullptr;
  const std::vector<Eigen::MatrixXd>* K = nullptr;
  double alpha = 1;
};

bool Rollout(const mjModel* m, const mjData* start, const TrajectoryCost& cost, int horizon,
             mjData* d, Trajectory& tr, const Feedback* feedback = nullptr) {
  const int nu = m->nu, nv = m->nv, n = StateDim(m);
  tr.qpos.resize((horizon + 1) * m->nq);
  tr.qvel.resize((horizon + 1) * nv);
  tr.act.resize((horizon + 1) * m->na);
  tr.warmstart.resize((horizon + 1) * nv);
  tr.time.resize(horizon + 1);
  tr.controls.resize(horizon * nu);
  mj_copyData(d, m, start);
  tr.cost = 0;
  Eigen::VectorXd dx(n);
  for (int t = 0; t < horizon; ++t) {
    mj_forward(m, d);
    StoreState(m, d, t, tr);
    double* u = tr.controls.data() + t * nu;
    if (feedback) {
      const Trajectory& nom = *feedback->nominal;
      mj_differentiatePos(m, dx.data(), 1.0, nom.qpos.data() + t * m->nq, d->qpos);
      for (int i = 0; i < nv; ++i) dx[nv + i] = d->qvel[i] - nom.qvel[t * nv + i];
      for (int i = 0; i < m->na; ++i) dx[2 * nv + i] = d->act[i] - nom.act[t * m->na + i];
      const Eigen::VectorXd du = feedback->alpha * (*feedback->k)[t] + (*feedback->K)[t] * dx;
      for (int i = 0; i < nu; ++i) u[i] = nom.controls[t * nu + i] + du[i];
    }
    ClampControls(m, u);
    std::copy_n(u, nu, d->ctrl);
    tr.cost += cost.Running(m, d, u, t, nullptr);
    mj_step(m, d);
    if (!Finite(d->qpos, m->nq) || !Finite(d->qvel, nv)) return false;
  }
  mj_forward(m, d);
  StoreState(m, d, horizon, tr);
  tr.cost += cost.Terminal(m, d, nullptr);
  return std::isfinite(tr.cost);
}

}  // namespace

double SiteReachCost::Distance(const mjData* d) const {
  return (Eigen::Map<const Eigen::Vector3d>(d->site_xpos + 3 * site_) - goal_).norm();
}

namespace {

// The rotation taking `goal` to a site's orientation, as a world-frame rotation vector.
Eigen::Vector3d TurnError(const mjData* d, int site, const Eigen::Quaterniond& goal) {
  const Eigen::Matrix3d r = Eigen::Map<const RowMatrix>(d->site_xmat + 9 * site, 3, 3);
  const Eigen::AngleAxisd turn(Eigen::Quaterniond(r) * goal.conjugate());
  return turn.angle() * turn.axis();
}

}  // namespace

double SiteReachCost::Angle(const mjData* d) const {
  return turn_site_ < 0 ? 0.0 : TurnError(d, turn_site_, turn_goal_).norm();
}

double SiteReachCost::SiteTerm(const mjModel* m, const mjData* d, double weight,
                               CostModel* model) const {
  if (weight == 0) return 0;
  const Eigen::Vector3d r = Eigen::Map<const Eigen::Vector3d>(d->site_xpos + 3 * site_) - goal_;
  const bool turn = turn_site_ >= 0 && turn_weight_ > 0;
  const Eigen::Vector3d e = turn ? TurnError(d, turn_site_, turn_goal_) : Eigen::Vector3d::Zero();
  if (model) {
    // Gauss-Newton on both residuals: the position's through the site's Jacobian, the angle's
    // (small, or near enough) through the turned site's rotational one.
    RowMatrix jac(3, m->nv);
    mj_jacSite(m, const_cast<mjData*>(d), jac.data(), nullptr, site_);
    model->lx.head(m->nv) += 2 * weight * jac.transpose() * r;
    model->lxx.topLeftCorner(m->nv, m->nv) += 2 * weight * jac.transpose() * jac;
    if (turn) {
      mj_jacSite(m, const_cast<mjData*>(d), nullptr, jac.data(), turn_site_);
      model->lx.head(m->nv) += 2 * weight * turn_weight_ * jac.transpose() * e;
      model->lxx.topLeftCorner(m->nv, m->nv) += 2 * weight * turn_weight_ * jac.transpose() * jac;
    }
  }
  return weight * (r.squaredNorm() + turn_weight_ * e.squaredNorm());
}

double SiteReachCost::Running(const mjModel* m, const mjData* d, const double* u, int,
                              CostModel* model) const {
  const Eigen::Map<const Eigen::VectorXd> uu(u, m->nu);
  const Eigen::VectorXd du =
      control_ref.size() == m->nu ? Eigen::VectorXd(uu - control_ref) : Eigen::VectorXd(uu);
  const Eigen::Map<const Eigen::VectorXd> qvel(d->qvel, m->nv);
  if (model) {
    model->lu += 2 * control * du;
    model->luu.diagonal().array() += 2 * control;
    model->lx.segment(m->nv, m->nv) += 2 * motion * qvel;
    model->lxx.block(m->nv, m->nv, m->nv, m->nv).diagonal().array() += 2 * motion;
  }
  return SiteTerm(m, d, running, model) + control * du.squaredNorm() + motion * qvel.squaredNorm();
}

double SiteReachCost::Terminal(const mjModel* m, const mjData* d, CostModel* model) const {
  const Eigen::Map<const Eigen::VectorXd> qvel(d->qvel, m->nv);
  if (model) {
    model->lx.segment(m->nv, m->nv) += 2 * velocity * qvel;
    model->lxx.block(m->nv, m->nv, m->nv, m->nv).diagonal().array() += 2 * velocity;
  }
  return SiteTerm(m, d, terminal, model) + velocity * qvel.squaredNorm();
}

double TrajectoryCostOf(const mjModel* m, const mjData* start, const TrajectoryCost& cost,
                        const std::vector<double>& controls) {
  if (m->nu == 0 || controls.size() % m->nu != 0)
    throw core::Error("trajectory cost: " + std::to_string(controls.size()) +
                      " controls are not whole steps of " + std::to_string(m->nu));
  DataPtr d = MakeData(m);
  Trajectory tr;
  tr.controls = controls;
  const int horizon = int(controls.size()) / m->nu;
  if (!Rollout(m, start, cost, horizon, d.get(), tr))
    throw core::NumericError("trajectory cost: the rollout diverged");
  return tr.cost;
}

IlqrResult OptimizeTrajectory(const mjModel* m, const mjData* start, const TrajectoryCost& cost,
                              int horizon, std::vector<double> initial,
                              const IlqrOptions& options) {
  const int nu = m->nu, n = StateDim(m);
  if (nu == 0) throw core::Error("trajectory optimization: the model has no actuators");
  if (horizon <= 0) throw core::Error("trajectory optimization: the horizon must be positive");
  if (options.linearize_every <= 0)
    throw core::Error("trajectory optimization: linearize_every must be positive");
  if (initial.empty())
    for (int t = 0; t < horizon; ++t) initial.insert(initial.end(), start->ctrl, start->ctrl + nu);
  if (int(initial.size()) != horizon * nu)
    throw core::Error("trajectory optimization: " + std::to_string(initial.size()) +
                      " initial controls for " + std::to_string(horizon) + " steps of " +
                      std::to_string(nu));
  if (!Finite(initial.data(), int(initial.size())))
    throw core::NumericError("trajectory optimization: the initial controls hold NaN or inf");

  DataPtr d = MakeData(m);
  Trajectory nominal, candidate;
  nominal.controls = std::move(initial);
  if (!Rollout(m, start, cost, horizon, d.get(), nominal))
    throw core::NumericError("trajectory optimization: the initial rollout diverged");
  IlqrResult result;
  result.costs.push_back(nominal.cost);

  std::vector<RowMatrix> A(horizon, RowMatrix(n, n)), B(horizon, RowMatrix(n, nu));
  std::vector<CostModel> models(horizon + 1);
  std::vector<Eigen::VectorXd> k(horizon);
  std::vector<Eigen::MatrixXd> K(horizon);
  double mu = options.regularization;

  for (int iteration = 0; iteration < options.iterations; ++iteration) {
    // Linearize the dynamics and quadratize the cost along the nominal trajectory.
    for (int t = 0; t <= horizon; ++t) {
      mj_copyData(d.get(), m, start);
      LoadState(m, nominal, t, d.get());
      models[t] = ZeroModel(m);
      if (t == horizon) {
        mj_forward(m, d.get());
        cost.Terminal(m, d.get(), &models[t]);
        break;
      }
      std::copy_n(nominal.controls.data() + t * nu, nu, d->ctrl);
      mj_forward(m, d.get());
      cost.Running(m, d.get(), nominal.controls.data() + t * nu, t, &models[t]);
      if (t % options.linearize_every == 0) {
        mjd_transitionFD(m, d.get(), options.fd_epsilon, options.fd_centered, A[t].data(),
                         B[t].data(), nullptr, nullptr);
      } else {
        A[t] = A[t - 1];
        B[t] = B[t - 1];
      }
    }

    // Backward pass, raising the regularization until every Quu is positive definite.
    bool accepted = false;
    while (!accepted && mu <= options.max_regularization) {
      Eigen::VectorXd vx = models[horizon].lx;
      Eigen::MatrixXd vxx = models[horizon].lxx;
      double dv1 = 0, dv2 = 0;  // predicted change: alpha * dv1 + alpha^2 * dv2
      bool ok = true;
      for (int t = horizon - 1; t >= 0 && ok; --t) {
        const CostModel& l = models[t];
        const Eigen::VectorXd qx = l.lx + A[t].transpose() * vx;
        const Eigen::VectorXd qu = l.lu + B[t].transpose() * vx;
        const Eigen::MatrixXd qxx = l.lxx + A[t].transpose() * vxx * A[t];
        const Eigen::MatrixXd qux = B[t].transpose() * vxx * A[t];
        Eigen::MatrixXd quu = l.luu + B[t].transpose() * vxx * B[t];
        quu.diagonal().array() += mu;
        const Eigen::LLT<Eigen::MatrixXd> llt(quu);
        if (llt.info() != Eigen::Success) {
          ok = false;
          break;
        }
        k[t] = -llt.solve(qu);
        K[t] = -llt.solve(qux);
        dv1 += k[t].dot(qu);
        dv2 += 0.5 * k[t].dot(quu * k[t]);
        vx = qx + K[t].transpose() * quu * k[t] + K[t].transpose() * qu + qux.transpose() * k[t];
        vxx = qxx + K[t].transpose() * quu * K[t] + K[t].transpose() * qux + qux.transpose() * K[t];
        vxx = 0.5 * (vxx + vxx.transpose());
      }
      if (!ok) {
        mu *= 10;
        continue;
      }
      // Forward pass: a backtracking line search on the feedforward step.
      for (double alpha = 1.0; alpha > 1e-3 && !accepted; alpha *= 0.5) {
        const Feedback feedback{&nominal, &k, &K, alpha};
        const double predicted = -(alpha * dv1 + alpha * alpha * dv2);
        if (Rollout(m, start, cost, horizon, d.get(), candidate, &feedback) &&
            nominal.cost - candidate.cost >
                options.min_reduction_ratio * std::max(predicted, 0.0) &&
            candidate.cost < nominal.cost)
          accepted = true;
      }
      if (!accepted) mu *= 10;
    }
    if (!accepted) {
      result.stalled = true;
      break;
    }
    mu = std::max(options.regularization, mu / 10);
    const double improvement = (nominal.cost - candidate.cost) / std::max(1e-12, nominal.cost);
    std::swap(nominal, candidate);
    result.costs.push_back(nominal.cost);
    result.iterations = iteration + 1;
    if (improvement < options.tolerance) {
      result.converged = true;
      break;
    }
  }
  result.controls = nominal.controls;
  return result;
}

}  // namespace twinforge::sim
