// The robot alone, posed at measured joints: cuts it out of depth images and samples its
// surface. A camera (real or proxy) sees the arm; scans and policy clouds must not, so both
// remove it by forward kinematics, here.
#pragma once

#include <memory>
#include <vector>

#include "sim/camera.h"
#include "sim/robot.h"

namespace twinforge::sim {

class RobotMask {
 public:
  explicit RobotMask(const RobotSpec& spec);
  ~RobotMask();

  // Poses the robot: arm joints and the opening between the fingers (m).
  void Pose(const ArmVector& q, double gripper_width);
  // Zeroes pixels of `depth` (metres, 0 = none) where the posed robot is in front of, or within
  // `margin` of, the measured depth. The robot's silhouette is grown by `grow` pixels first: a
  // camera a few mm off its reported pose sees the robot's edges a pixel or two away, and those
  // slivers would otherwise pile up into ghost surfaces in a fused scan. Returns how many.
  int Remove(const Camera& camera, std::vector<float>& depth, double margin,
             int grow = kArmGrowPixels);
  // Points on the posed robot inside `workspace` (base frame); see SurfaceSampler::Transform.
  int Surface(const Workspace& workspace, float* xyz) const;
  int surface_capacity() const { return sampler_.capacity(); }

 private:
  ModelPtr model_;  // the robot alone, base at the origin
  DataPtr data_;
  RobotIndex index_;
  SurfaceSampler sampler_;
  std::unique_ptr<RayCaster> caster_;  // rebuilt when the camera's intrinsics change
  std::vector<float> robot_depth_, grown_;
};

}  // namespace twinforge::sim
