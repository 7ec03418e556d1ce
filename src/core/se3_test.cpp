#include "core/se3.h"

#include <gtest/gtest.h>

namespace twinforge::core {
namespace {

TEST(Se3, ComposeAndInverse) {
  Pose a{{0.1, -0.2, 0.3}, FromRollPitchYaw(0.1, 0.2, 0.3)};
  Pose b{{1.0, 0.0, -0.5}, AxisAngle(Vec3(1, 1, 0), 0.7)};
  const Vec3 p(0.3, 0.4, 0.5);
  EXPECT_TRUE(((a * b) * p).isApprox(a * (b * p), 1e-12));
  EXPECT_TRUE(((a * a.Inverse()) * p).isApprox(p, 1e-12));
  EXPECT_TRUE(Pose::FromMatrix(a.Matrix()).Matrix().isApprox(a.Matrix(), 1e-12));
}

TEST(Se3, RollPitchYawRoundTrip) {
  const Vec3 rpy(0.3, -0.4, 2.5);
  EXPECT_TRUE(ToRollPitchYaw(FromRollPitchYaw(rpy.x(), rpy.y(), rpy.z())).isApprox(rpy, 1e-12));
  // Yaw rotates x towards y.
  EXPECT_TRUE((FromRollPitchYaw(0, 0, M_PI / 2) * Vec3::UnitX()).isApprox(Vec3::UnitY(), 1e-12));
}

TEST(Se3, LogExpAreInverse) {
  for (const Vec3& v : {Vec3(0.1, 0.2, -0.3), Vec3(0, 0, 3.0), Vec3(1e-14, 0, 0)}) {
    EXPECT_TRUE(LogMap(ExpMap(v)).isApprox(v, 1e-9) || (v.norm() < 1e-10)) << v.transpose();
  }
  EXPECT_NEAR(AngleBetween(Yaw(0.2), Yaw(-0.3)), 0.5, 1e-12);
}

TEST(Se3, MujocoQuaternionOrder) {
  const double wxyz[4] = {0.0, 0.0, 0.0, 1.0};  // 180 deg about z
  EXPECT_TRUE((QuatFromMj(wxyz) * Vec3::UnitX()).isApprox(-Vec3::UnitX(), 1e-12));
  double back[4];
  QuatToMj(Yaw(0.5), back);
  EXPECT_NEAR(back[0], std::cos(0.25), 1e-12);
  EXPECT_NEAR(back[3], std::sin(0.25), 1e-12);
}

}  // namespace
}  // namespace twinforge::core
