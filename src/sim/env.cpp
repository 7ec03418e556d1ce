#include "sim/env.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "core/error.h"
#include "sim/model.h"
#include "sim/servo_lag.h"

namespace twinforge::sim {

namespace {

template <class T>
void CopyArray(T* dst, const T* src, int count) {
  std::memcpy(dst, src, sizeof(T) * count);
}

}  // namespace

Env::Env(std::shared_ptr<const Task> task, int env_id)
    : task_(std::move(task)),
      env_id_(env_id),
      model_(mj_copyModel(nullptr, task_->model())),
      data_(MakeData(model_.get())),
      kinematics_(task_->robot()) {
  const auto& spec = task_->spec();
  base_.translation = Eigen::Vector3d(spec.robot_position.data());
  base_.rotation = core::Yaw(spec.robot_yaw);
  const auto& r = task_->index().robot;
  for (int k = 0; k < kArmDof; ++k) robot_dofs_.push_back(r.arm_dof[k]);
  for (int k = 0; k < 2; ++k) robot_dofs_.push_back(r.finger_dof[k]);
  if (!spec.control.servo.ideal())
    servo_ = std::make_shared<ServoLag>(spec.control.servo, r, spec.control.timestep);
  Reset(0, 0);
}

void Env::RestoreNominalModel() {
  const mjModel* n = task_->model();
  mjModel* m = model_.get();
  CopyArray(m->body_pos, n->body_pos, 3 * m->nbody);
  CopyArray(m->body_quat, n->body_quat, 4 * m->nbody);
  CopyArray(m->body_mass, n->body_mass, m->nbody);
  CopyArray(m->body_inertia, n->body_inertia, 3 * m->nbody);
  CopyArray(m->geom_friction, n->geom_friction, 3 * m->ngeom);
  CopyArray(m->geom_size, n->geom_size, 3 * m->ngeom);
  CopyArray(m->geom_rbound, n->geom_rbound, m->ngeom);
  CopyArray(m->geom_rgba, n->geom_rgba, 4 * m->ngeom);
  CopyArray(m->dof_damping, n->dof_damping, m->nv);
  CopyArray(m->dof_frictionloss, n->dof_frictionloss, m->nv);
  CopyArray(m->actuator_gainprm, n->actuator_gainprm, mjNGAIN * m->nu);
  CopyArray(m->actuator_biasprm, n->actuator_biasprm, mjNBIAS * m->nu);
  CopyArray(m->actuator_forcerange, n->actuator_forcerange, 2 * m->nu);
}

void Env::Reset(uint64_t seed, int level) {
  if (level < 0 || level > 3)
    throw core::ConfigError("", "level",
                            "expected a randomization level 0..3, got " + std::to_string(level));
  rng_ = core::Rng(seed, 0x7e1f);
  level_ = level;
  steps_ = 0;
  substep_count_ = 0;
  gripper_ = {};
  disturbances_.clear();
  RestoreNominalModel();
  mj_resetData(model_.get(), data_.get());  // qpos0, zero qvel/act/ctrl/forces/warm-start, time

  const auto& spec = task_->spec();
  const auto& r = task_->index().robot;
  ArmVector home = kinematics_.home();
  if (level >= 1) {
    for (int k = 0; k < kArmDof; ++k)
      home[k] += rng_.Uniform(-1.0, 1.0) * spec.randomization.robot_joint_noise;
    RandomizePoses();
  }
  if (level >= 2) PlaceDistractors();
  if (level >= 3) ScheduleDisturbances();
  if (level >= spec.randomization.physics.from_level) RandomizePhysics();

  home = home.cwiseMax(r.lower).cwiseMin(r.upper);
  for (int k = 0; k < kArmDof; ++k) {
    data_->qpos[r.arm_qpos[k]] = home[k];
    data_->ctrl[r.arm_actuator[k]] = home[k];
  }
  for (int k = 0; k < 2; ++k) {
    data_->qpos[r.finger_qpos[k]] = task_->robot().gripper_open;
    data_->ctrl[r.finger_actuator[k]] = task_->robot().gripper_open;
  }
  mj_forward(model_.get(), data_.get());
  if (servo_) servo_->Reset(data_.get());
  last_bad_qacc_ = data_->warning[mjWARN_BADQACC].number;
}

void Env::RandomizePoses() {
  mjModel* m = model_.get();
  const mjModel* n = task_->model();
  const auto& groups = task_->spec().randomization.groups;
  for (std::size_t g = 0; g < groups.size(); ++g) {
    const auto& group = groups[g];
    const Eigen::Vector3d offset(rng_.Uniform(group.x[0], group.x[1]),
                                 rng_.Uniform(group.y[0], group.y[1]),
                                 rng_.Uniform(group.z[0], group.z[1]));
    const core::Quat turn = core::Yaw(rng_.Uniform(group.yaw[0], group.yaw[1]));
    Eigen::Vector3d pivot = Eigen::Vector3d::Zero();
    const auto& bodies = task_->index().group_bodies[g];
    for (std::size_t i = 0; i < bodies.size(); ++i) {
      const int b = bodies[i];
      const int free = FreeJointOf(m, b);
      double* pos = free >= 0 ? data_->qpos + m->jnt_qposadr[free] : m->body_pos + 3 * b;
      double* quat = pos + (free >= 0 ? 3 : 0);
      if (free < 0) quat = m->body_quat + 4 * b;
      const Eigen::Vector3d p = free >= 0 ? Eigen::Vector3d(n->qpos0 + n->jnt_qposadr[free])
                                          : Eigen::Vector3d(n->body_pos + 3 * b);
      const core::Quat q =
          core::QuatFromMj(free >= 0 ? n->qpos0 + n->jnt_qposadr[free] + 3 : n->body_quat + 4 * b);
      if (i == 0) pivot = p;
      const Eigen::Vector3d moved = pivot + turn * (p - pivot) + offset;
      std::copy(moved.data(), moved.data() + 3, pos);
      core::QuatToMj(turn * q, quat);
    }
  }
}

void Env::PlaceDistractors() {
  mjModel* m = model_.get();
  const auto& spec = task_->spec().randomization.distractors;
  const auto& index = task_->index();
  mj_kinematics(m, data_.get());                 // object positions after pose randomization
  std::vector<Eigen::Vector2d>& taken = taken_;  // reused: resets happen inside VecEnv::Step
  taken.clear();
  for (int b : index.object_bodies) taken.emplace_back(data_->xpos[3 * b], data_->xpos[3 * b + 1]);
  for (const auto& bodies : index.group_bodies)
    for (int b : bodies) taken.emplace_back(data_->xpos[3 * b], data_->xpos[3 * b + 1]);
  const int count = static_cast<int>(rng_.Int(spec.count[0], spec.count[1]));
  for (int i = 0; i < count; ++i) {
    const int body = index.distractor_bodies[i];
    const int geom = index.distractor_geoms[i];
    const int mocap = m->body_mocapid[body];
    const double s = rng_.Uniform(spec.size[0], spec.size[1]);
    const Eigen::Vector3d half(s, s * rng_.Uniform(0.6, 1.4), s * rng_.Uniform(0.6, 1.6));
    for (int attempt = 0; attempt < 50; ++attempt) {
      const Eigen::Vector2d xy(rng_.Uniform(spec.region_min[0], spec.region_max[0]),
                               rng_.Uniform(spec.region_min[1], spec.region_max[1]));
      const bool clear = std::all_of(taken.begin(), taken.end(), [&](const Eigen::Vector2d& t) {
        return (t - xy).norm() > spec.clearance + s;
      });
      if (!clear) continue;
      taken.push_back(xy);
      data_->mocap_pos[3 * mocap] = xy.x();
      data_->mocap_pos[3 * mocap + 1] = xy.y();
      data_->mocap_pos[3 * mocap + 2] = spec.region_min[2] + half.z();
      core::QuatToMj(core::Yaw(rng_.Uniform(-M_PI, M_PI)), data_->mocap_quat + 4 * mocap);
      std::copy(half.data(), half.data() + 3, m->geom_size + 3 * geom);
      m->geom_rbound[geom] = half.norm();
      for (int c = 0; c < 3; ++c) m->geom_rgba[4 * geom + c] = rng_.Uniform(0.05, 0.95);
      break;
    }
  }
}

void Env::ScheduleDisturbances() {
  const mjModel* m = model_.get();
  const auto& spec = task_->spec();
  const int substeps = spec.control.substeps;
  const auto& specs = spec.randomization.disturbances;
  for (std::size_t k = 0; k < specs.size(); ++k) {
    const auto& d = specs[k];
    const auto& ids = task_->index().disturbances[k];
    if (!rng_.Bernoulli(d.probability)) continue;
    ActiveDisturbance a;
    const double start = rng_.Uniform(d.window[0], d.window[1]) * spec.horizon;
    a.start_substep = static_cast<int>(start * substeps);
    a.end_substep = a.start_substep + std::max(1, static_cast<int>(d.duration / m->opt.timestep));
    const double magnitude = rng_.Uniform(d.force[0], d.force[1]);
    if (ids.body >= 0) {
      a.body = ids.body;
      const double angle = rng_.Uniform(-M_PI, M_PI);
      a.force = magnitude * Eigen::Vector3d(std::cos(angle), std::sin(angle), 0.0);
      a.at = Eigen::Vector3d(d.at.data());
    } else {
      a.dof = ids.dof;
      a.generalized = magnitude;
    }
    disturbances_.push_back(a);
  }
}

void Env::RandomizePhysics() {
  mjModel* m = model_.get();
  const auto& p = task_->spec().randomization.physics;
  const int mount = task_->index().robot_mount;
  const double friction = rng_.Uniform(p.friction[0], p.friction[1]);
  const double mass = rng_.Uniform(p.mass[0], p.mass[1]);
  const double damping = rng_.Uniform(p.damping[0], p.damping[1]);
  const double gain = rng_.Uniform(p.actuator_gain[0], p.actuator_gain[1]);
  const double frictionloss = rng_.Uniform(p.frictionloss[0], p.frictionloss[1]);
  const double grip_force = rng_.Uniform(p.grip_force[0], p.grip_force[1]);
  for (int g = 0; g < m->ngeom; ++g)
    if (!InSubtree(m, m->geom_bodyid[g], mount)) m->geom_friction[3 * g] *= friction;
  for (int b = 1; b < m->nbody; ++b)
    if (!InSubtree(m, b, mount)) {
      m->body_mass[b] *= mass;
      for (int c = 0; c < 3; ++c) m->body_inertia[3 * b + c] *= mass;
    }
  for (int v = 0; v < m->nv; ++v)
    if (!InSubtree(m, m->dof_bodyid[v], mount)) {
      m->dof_damping[v] *= damping;
      m->dof_frictionloss[v] *= frictionloss;
    }
  for (int a = 0; a < m->nu; ++a) {
    m->actuator_gainprm[mjNGAIN * a] *= gain;
    m->actuator_biasprm[mjNBIAS * a + 1] *= gain;
  }
  for (int a : task_->index().robot.finger_actuator) {
    m->actuator_forcerange[2 * a] *= grip_force;
    m->actuator_forcerange[2 * a + 1] *= grip_force;
  }
}

void Env::ApplyForces(int substep) {
  mjData* d = data_.get();
  // Gravity and Coriolis compensation of the arm, from the last step's bias forces.
  for (int dof : robot_dofs_) d->qfrc_applied[dof] = d->qfrc_bias[dof];
  for (const auto& a : disturbances_) {
    const bool on = substep >= a.start_substep && substep < a.end_substep;
    if (a.body >= 0) {
      // A force at a point is the force at the centre of mass plus its moment about it.
      const Eigen::Map<const Eigen::Matrix<mjtNum, 3, 3, Eigen::RowMajor>> rotation(d->xmat +
                                                                                    9 * a.body);
      const Eigen::Vector3d point = Eigen::Vector3d(d->xpos + 3 * a.body) + rotation * a.at;
      const Eigen::Vector3d torque =
          (point - Eigen::Vector3d(d->xipos + 3 * a.body)).cross(a.force);
      for (int c = 0; c < 3; ++c) {
        d->xfrc_applied[6 * a.body + c] = on ? a.force[c] : 0.0;
        d->xfrc_applied[6 * a.body + 3 + c] = on ? torque[c] : 0.0;
      }
    } else {
      d->qfrc_applied[a.dof] = on ? a.generalized : 0.0;
    }
  }
}

StepResult Env::Step(const Action& action) {
  return StepTargets(ActionToJointTargets(kinematics_, ArmPositions(), action,
                                          task_->spec().control.limits, gripper_));
}

StepResult Env::StepTargets(const JointTargets& targets, SubstepHook* hook) {
  const auto& spec = task_->spec();
  const auto& r = task_->index().robot;
  if (!targets.arm.allFinite() || !std::isfinite(targets.finger))
    throw core::NumericError("joint targets are not finite");
  gripper_.closure = targets.closure;
  for (int k = 0; k < kArmDof; ++k) data_->ctrl[r.arm_actuator[k]] = targets.arm[k];
  for (int k = 0; k < 2; ++k) data_->ctrl[r.finger_actuator[k]] = targets.finger;
  if (!hook && servo_) {
    servo_->Command(targets);
    hook = servo_.get();
  }
  for (int s = 0; s < spec.control.substeps; ++s) {
    ApplyForces(substep_count_++);
    if (hook) hook->BeforeSubstep(model_.get(), data_.get());
    mj_step(model_.get(), data_.get());
  }
  ++steps_;
  StepResult result;
  result.unstable = data_->warning[mjWARN_BADQACC].number != last_bad_qacc_;
  last_bad_qacc_ = data_->warning[mjWARN_BADQACC].number;
  result.success = !result.unstable && Success();
  result.reward = result.success ? 1.0f : 0.0f;
  result.done = result.unstable || steps_ >= spec.horizon;
  return result;
}

double Env::Measure(const TaskIndex::Predicate& p) const {
  const mjData* d = data_.get();
  switch (p.type) {
    case PredicateType::kSiteDistanceBelow:
      return (Eigen::Vector3d(d->site_xpos + 3 * p.a) - Eigen::Vector3d(d->site_xpos + 3 * p.b))
          .norm();
    case PredicateType::kJointAbove:
      return d->qpos[model_->jnt_qposadr[p.a]];
    case PredicateType::kAxisUpright:
      return (Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(d->xmat + 9 * p.a) *
              p.axis)
          .z();
    case PredicateType::kGripperReleased:
      return FingerOpening();
  }
  return 0;
}

namespace {

// Whether a predicate holds, given what it measures (Env::Measure).
bool Holds(const TaskIndex::Predicate& p, double v) {
  switch (p.type) {
    case PredicateType::kSiteDistanceBelow:
      return v < p.threshold;
    case PredicateType::kAxisUpright:
      return v >= p.threshold;
    case PredicateType::kJointAbove:
    case PredicateType::kGripperReleased:
      return v > p.threshold;
  }
  return false;
}

}  // namespace

bool Env::Success() const {
  for (const auto& p : task_->index().predicates)
    if (!Holds(p, Measure(p))) return false;
  return true;
}

double Env::SuccessCloseness() const {
  double closeness = 1;
  for (const auto& p : task_->index().predicates) {
    const double v = Measure(p);
    if (Holds(p, v)) continue;
    // Each failing predicate's share; one with threshold <= 0 shares 0.
    const double share = p.threshold <= 0                              ? 0
                         : p.type == PredicateType::kSiteDistanceBelow ? p.threshold / v
                                                                       : v / p.threshold;
    closeness *= std::clamp(share, 0.0, 1.0);
  }
  return closeness;
}

ArmVector Env::ArmPositions() const {
  ArmVector q;
  for (int k = 0; k < kArmDof; ++k) q[k] = data_->qpos[task_->index().robot.arm_qpos[k]];
  return q;
}

double Env::FingerOpening() const {
  const auto& r = task_->index().robot;
  return 0.5 * (data_->qpos[r.finger_qpos[0]] + data_->qpos[r.finger_qpos[1]]);
}

core::Pose Env::SitePose(int site) const {
  return base_.Inverse() * SiteWorldPose(data_.get(), site);
}

core::Pose Env::BodyPose(int body) const {
  const core::Pose world{Eigen::Vector3d(data_->xpos + 3 * body),
                         core::QuatFromMj(data_->xquat + 4 * body)};
  return base_.Inverse() * world;
}

void Env::PoseRobot(const ArmVector& q, double finger, double closure) {
  const auto& r = task_->index().robot;
  mjData* d = data_.get();
  for (int i = 0; i < kArmDof; ++i) d->qpos[r.arm_qpos[i]] = q[i];
  for (int i = 0; i < 2; ++i) d->qpos[r.finger_qpos[i]] = finger;
  mju_zero(d->qvel, model_->nv);
  gripper_.closure = closure;
  mj_kinematics(model_.get(), d);
}

void Env::PlaceBody(int body, const core::Pose& pose) {
  mjModel* m = model_.get();
  const int free = body >= 0 && body < m->nbody ? FreeJointOf(m, body) : -1;
  const core::Pose world = base_ * pose;
  if (free < 0 && body > 0 && body < m->nbody && m->body_parentid[body] == 0 &&
      m->body_jntnum[body] == 0) {
    // Welded to the world (a griddle): moved in this env's model, as RandomizePoses moves it.
    std::copy(world.translation.data(), world.translation.data() + 3, m->body_pos + 3 * body);
    core::QuatToMj(world.rotation, m->body_quat + 4 * body);
    mj_kinematics(m, data_.get());
    return;
  }
  if (free < 0) {
    const char* name = body >= 0 && body < m->nbody ? mj_id2name(m, mjOBJ_BODY, body) : nullptr;
    throw core::Error(task_->spec().name + ": body " + (name ? name : std::to_string(body)) +
                      " has no free joint to place it by, nor hangs welded from the world");
  }
  double* qpos = data_->qpos + m->jnt_qposadr[free];
  std::copy(world.translation.data(), world.translation.data() + 3, qpos);
  core::QuatToMj(world.rotation, qpos + 3);
  mju_zero(data_->qvel + m->jnt_dofadr[free], 6);
  mj_kinematics(m, data_.get());
}

core::Pose Env::EePose() const { return SitePose(task_->index().robot.ee_site); }

void MakeProprio(const core::Pose& ee, double finger_left, double finger_right, float* out) {
  // One sign per orientation: the one nearer the tool pointing straight down (the base's x axis
  // turned half a turn; w, x, y, z = 0, 1, 0, 0), where tools work. The sign then never flips in
  // the workspace; the choice w >= 0 flipped it each time a top-down tool turned through w = 0,
  // and a policy saw one pose as two inputs far apart.
  core::Quat q = ee.rotation;
  if (q.x() < 0) q.coeffs() = -q.coeffs();
  const double values[kProprioDim] = {
      ee.translation.x(), ee.translation.y(), ee.translation.z(), q.w(), q.x(), q.y(), q.z(),
      finger_left,        finger_right};
  for (int i = 0; i < kProprioDim; ++i) out[i] = static_cast<float>(values[i]);
}

void Env::Proprio(float* out) const {
  const auto& r = task_->index().robot;
  MakeProprio(EePose(), data_->qpos[r.finger_qpos[0]], data_->qpos[r.finger_qpos[1]], out);
}

void Env::State(float* out) const {
  Proprio(out);
  int i = kProprioDim;
  const core::Pose inverse_base = base_.Inverse();
  for (int b : task_->index().object_bodies) {
    core::Pose world{Eigen::Vector3d(data_->xpos + 3 * b), core::QuatFromMj(data_->xquat + 4 * b)};
    const core::Pose local = inverse_base * world;
    core::Quat q = local.rotation;
    if (q.w() < 0) q.coeffs() = -q.coeffs();
    const double values[7] = {local.translation.x(),
                              local.translation.y(),
                              local.translation.z(),
                              q.w(),
                              q.x(),
                              q.y(),
                              q.z()};
    for (double v : values) out[i++] = static_cast<float>(v);
  }
  for (int j : task_->index().state_joints)
    out[i++] = static_cast<float>(data_->qpos[model_->jnt_qposadr[j]]);
}

}  // namespace twinforge::sim
