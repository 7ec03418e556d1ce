#include "sim/robot.h"

#include <Eigen/Dense>
#include <cmath>

#include "core/config.h"
#include "core/error.h"

namespace twinforge::sim {

RobotSpec LoadRobotSpec(const std::filesystem::path& path) {
  RobotSpec spec = core::LoadConfig<RobotSpec>(path);
  spec.file = std::filesystem::absolute(path);
  if (!std::filesystem::exists(spec.mjcf_path()))
    throw core::ConfigError(path.string(), "mjcf",
                            "file " + spec.mjcf_path().string() + " does not exist");
  return spec;
}

std::filesystem::path DefaultRobotPath() {
  return std::filesystem::path(TWINFORGE_ASSETS_DIR) / "robots/panda/robot.yaml";
}

RobotIndex RobotIndex::Resolve(const mjModel* m, const RobotSpec& spec) {
  RobotIndex index;
  auto id = [&](mjtObj type, const std::string& name, const char* field) {
    const int i = mj_name2id(m, type, name.c_str());
    if (i < 0)
      throw core::ConfigError(
          spec.file.string(), field,
          "the model has no " +
              std::string(field == std::string("ee_site") ? "site" : "joint/actuator") +
              " named '" + name + "'");
    return i;
  };
  for (int k = 0; k < kArmDof; ++k) {
    const int j = id(mjOBJ_JOINT, spec.arm_joints[k], "arm_joints");
    if (m->jnt_type[j] != mjJNT_HINGE && m->jnt_type[j] != mjJNT_SLIDE)
      throw core::ConfigError(spec.file.string(), "arm_joints",
                              "joint '" + spec.arm_joints[k] + "' must be a hinge or slide");
    index.arm_qpos[k] = m->jnt_qposadr[j];
    index.arm_dof[k] = m->jnt_dofadr[j];
    index.arm_actuator[k] = id(mjOBJ_ACTUATOR, spec.arm_joints[k], "arm_joints");
    index.lower[k] = m->jnt_range[2 * j];
    index.upper[k] = m->jnt_range[2 * j + 1];
  }
  for (int k = 0; k < 2; ++k) {
    const int j = id(mjOBJ_JOINT, spec.finger_joints[k], "finger_joints");
    index.finger_qpos[k] = m->jnt_qposadr[j];
    index.finger_dof[k] = m->jnt_dofadr[j];
    index.finger_actuator[k] = id(mjOBJ_ACTUATOR, spec.finger_joints[k], "finger_joints");
  }
  index.ee_site = id(mjOBJ_SITE, spec.ee_site, "ee_site");
  return index;
}

Kinematics::Kinematics(const RobotSpec& spec)
    : spec_(spec),
      model_(LoadModel(spec.mjcf_path())),
      data_(MakeData(model_.get())),
      index_(RobotIndex::Resolve(model_.get(), spec)),
      jacp_(3 * model_->nv),
      jacr_(3 * model_->nv) {}

void Kinematics::SetArm(const ArmVector& q) const {
  for (int k = 0; k < kArmDof; ++k) data_->qpos[index_.arm_qpos[k]] = q[k];
  mj_kinematics(model_.get(), data_.get());
  mj_comPos(model_.get(), data_.get());
}

core::Pose Kinematics::EePose(const ArmVector& q) const {
  SetArm(q);
  return SiteWorldPose(data_.get(), index_.ee_site);
}

Eigen::Matrix<double, 6, kArmDof> Kinematics::Jacobian(const ArmVector& q) const {
  SetArm(q);
  const int nv = model_->nv;
  mj_jacSite(model_.get(), data_.get(), jacp_.data(), jacr_.data(), index_.ee_site);
  Eigen::Matrix<double, 6, kArmDof> j;
  for (int r = 0; r < 3; ++r)
    for (int k = 0; k < kArmDof; ++k) {
      j(r, k) = jacp_[r * nv + index_.arm_dof[k]];
      j(3 + r, k) = jacr_[r * nv + index_.arm_dof[k]];
    }
  return j;
}

ArmVector Kinematics::SolveIk(const ArmVector& q0, const core::Pose& target,
                              const IkOptions& options) const {
  const ArmVector lo = index_.lower.array() + options.limit_margin;
  const ArmVector hi = index_.upper.array() - options.limit_margin;
  ArmVector q = q0.cwiseMax(lo).cwiseMin(hi);
  for (int it = 0; it < options.iterations; ++it) {
    const core::Pose current = EePose(q);
    Eigen::Matrix<double, 6, 1> error;
    error.head<3>() = target.translation - current.translation;
    error.tail<3>() = core::LogMap(target.rotation * current.rotation.conjugate());
    if (error.head<3>().norm() < 1e-5 && error.tail<3>().norm() < 1e-4) break;
    Eigen::Matrix<double, 6, kArmDof> j = Jacobian(q);
    j.bottomRows<3>() *= options.rotation_weight;
    error.tail<3>() *= options.rotation_weight;
    const Eigen::Matrix<double, 6, 6> jjt =
        j * j.transpose() +
        options.damping * options.damping * Eigen::Matrix<double, 6, 6>::Identity();
    const ArmVector dq = j.transpose() * jjt.ldlt().solve(error);
    if (!dq.allFinite()) break;
    q = (q + dq).cwiseMax(lo).cwiseMin(hi);
  }
  return q;
}

}  // namespace twinforge::sim
