// A scene for the active camera's tests: a target that a wall hides from some views.
#pragma once

#include "samrl/active_camera.h"

namespace twinforge::samrl::testing {

using real2sim::BoxMesh;

// A red target on a blue table behind a blue wall on its +x side: seen from +x (azimuth 0) the
// wall hides it; seen from the sides or from above it is in full view.
inline real2sim::RasterMesh OccludedTarget() {
  const Eigen::Vector3d blue(0, 0, 1), red(1, 0, 0);
  return real2sim::JoinMeshes({BoxMesh({0.5, 0, -0.02}, {0.8, 0.8, 0.04}, blue),
                               BoxMesh({0.5, 0, 0.04}, {0.08, 0.08, 0.08}, red),
                               BoxMesh({0.62, 0, 0.12}, {0.03, 0.5, 0.24}, blue)});
}

inline core::PinholeIntrinsics Small() {
  core::PinholeIntrinsics k;
  k.width = 40;
  k.height = 30;
  k.fx = k.fy = 40;
  k.cx = 19.5;
  k.cy = 14.5;
  return k;
}

// A known score: how much of the image the red target covers.
inline torch::Tensor VisibleTarget(const real2sim::SoftImage& image) {
  return image.rgb.select(2, 0).mean() * 100.0;
}

inline OrbitMount Mount() {
  OrbitMount m;
  m.center = Eigen::Vector3d(0.5, 0, 0.05);
  m.radius = 0.7;
  m.min_azimuth = -1.2;
  m.max_azimuth = 1.2;
  m.min_elevation = 0.15;
  m.max_elevation = 1.2;
  return m;
}

}  // namespace twinforge::samrl::testing
