// Rigid transforms and rotations on Eigen, with MuJoCo's (w, x, y, z) quaternion order.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace twinforge::core {

using Vec3 = Eigen::Vector3d;
using Mat3 = Eigen::Matrix3d;
using Quat = Eigen::Quaterniond;

// A rigid transform: x' = rotation * x + translation.
struct Pose {
  Vec3 translation = Vec3::Zero();
  Quat rotation = Quat::Identity();

  static Pose Identity() { return {}; }
  // From a 4x4 homogeneous matrix.
  static Pose FromMatrix(const Eigen::Matrix4d& m);
  Eigen::Matrix4d Matrix() const;

  Pose operator*(const Pose& other) const;
  Vec3 operator*(const Vec3& point) const { return rotation * point + translation; }
  Pose Inverse() const;
};

// Rotation of `angle` radians about the unit `axis`.
Quat AxisAngle(const Vec3& axis, double angle);
// Intrinsic roll (x), pitch (y), yaw (z): R = Rz(yaw) * Ry(pitch) * Rx(roll).
Quat FromRollPitchYaw(double roll, double pitch, double yaw);
// Inverse of FromRollPitchYaw.
Vec3 ToRollPitchYaw(const Quat& q);

// Rotation vector (axis * angle, angle in [0, pi]) of q, and back.
Vec3 LogMap(const Quat& q);
Quat ExpMap(const Vec3& rotation_vector);

// Angle in [0, pi] between two orientations.
double AngleBetween(const Quat& a, const Quat& b);

// MuJoCo stores quaternions as (w, x, y, z).
Quat QuatFromMj(const double* wxyz);
void QuatToMj(const Quat& q, double* wxyz);

// Yaw-only rotation about +z.
inline Quat Yaw(double angle) { return AxisAngle(Vec3::UnitZ(), angle); }

}  // namespace twinforge::core
