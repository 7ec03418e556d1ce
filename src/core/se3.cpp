#include "core/se3.h"

#include <algorithm>
#include <cmath>

namespace twinforge::core {

Pose Pose::FromMatrix(const Eigen::Matrix4d& m) {
  Pose pose;
  pose.translation = m.block<3, 1>(0, 3);
  pose.rotation = Quat(Mat3(m.block<3, 3>(0, 0))).normalized();
  return pose;
}

Eigen::Matrix4d Pose::Matrix() const {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m.block<3, 3>(0, 0) = rotation.toRotationMatrix();
  m.block<3, 1>(0, 3) = translation;
  return m;
}

Pose Pose::operator*(const Pose& other) const {
  Pose out;
  out.rotation = (rotation * other.rotation).normalized();
  out.translation = rotation * other.translation + translation;
  return out;
}

Pose Pose::Inverse() const {
  Pose out;
  out.rotation = rotation.conjugate();
  out.translation = -(out.rotation * translation);
  return out;
}

Quat AxisAngle(const Vec3& axis, double angle) {
  return Quat(Eigen::AngleAxisd(angle, axis.normalized()));
}

Quat FromRollPitchYaw(double roll, double pitch, double yaw) {
  return (AxisAngle(Vec3::UnitZ(), yaw) * AxisAngle(Vec3::UnitY(), pitch) *
          AxisAngle(Vec3::UnitX(), roll))
      .normalized();
}

Vec3 ToRollPitchYaw(const Quat& q) {
  const Mat3 r = q.toRotationMatrix();
  const double pitch = std::asin(std::clamp(-r(2, 0), -1.0, 1.0));
  const double roll = std::atan2(r(2, 1), r(2, 2));
  const double yaw = std::atan2(r(1, 0), r(0, 0));
  return {roll, pitch, yaw};
}

Vec3 LogMap(const Quat& q_in) {
  Quat q = q_in.normalized();
  if (q.w() < 0) q.coeffs() = -q.coeffs();  // shortest rotation
  const Vec3 v = q.vec();
  const double s = v.norm();
  if (s < 1e-12) return 2.0 * v;  // small-angle limit
  const double angle = 2.0 * std::atan2(s, q.w());
  return v * (angle / s);
}

Quat ExpMap(const Vec3& rotation_vector) {
  const double angle = rotation_vector.norm();
  if (angle < 1e-12) {
    Quat q(1.0, 0.5 * rotation_vector.x(), 0.5 * rotation_vector.y(), 0.5 * rotation_vector.z());
    return q.normalized();
  }
  return Quat(Eigen::AngleAxisd(angle, rotation_vector / angle));
}

double AngleBetween(const Quat& a, const Quat& b) { return LogMap(a.conjugate() * b).norm(); }

Quat QuatFromMj(const double* wxyz) {
  return Quat(wxyz[0], wxyz[1], wxyz[2], wxyz[3]).normalized();
}

void QuatToMj(const Quat& q, double* wxyz) {
  wxyz[0] = q.w();
  wxyz[1] = q.x();
  wxyz[2] = q.y();
  wxyz[3] = q.z();
}

}  // namespace twinforge::core
