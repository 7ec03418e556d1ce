#include "reality/frame_cloud.h"

#include <algorithm>

namespace twinforge::reality {

std::vector<float> DepthMetres(const RgbdFrame& frame) {
  std::vector<float> depth(frame.depth.size());
  for (std::size_t i = 0; i < depth.size(); ++i) depth[i] = frame.depth[i] * 1e-3f;
  return depth;
}

FrameCloud::FrameCloud(const sim::RobotSpec& robot, const sim::WorkspaceSpec& workspace,
                       const Options& options, const core::Pose& camera_correction)
    : options_(options),
      camera_correction_(camera_correction),
      workspace_(sim::MakeWorkspace(workspace)),
      robot_(robot) {
  scratch_.resize(3 * std::size_t(robot_.surface_capacity()));
}

FrameCloud::~FrameCloud() = default;

int FrameCloud::RemoveArm(const Observation& observation, const sim::Camera& camera,
                          std::vector<float>& depth) {
  robot_.Pose(observation.q, observation.gripper_width);
  return robot_.Remove(camera, depth, options_.arm_margin);
}

void FrameCloud::Make(const Observation& observation, const RgbdFrame& frame, core::Rng& rng,
                      float* scene, float* arm) {
  const sim::Camera camera{frame.intrinsics, frame.extrinsics * camera_correction_};
  depth_ = DepthMetres(frame);
  RemoveArm(observation, camera, depth_);
  scratch_.resize(std::max(scratch_.size(), 3 * depth_.size()));
  const int n = sim::DepthToPoints(camera, depth_.data(), workspace_, scratch_.data());
  sim::ResamplePoints(scratch_.data(), n, options_.scene_points, rng, scene);
  const int arm_n = robot_.Surface(workspace_, scratch_.data());  // posed by RemoveArm
  sim::ResamplePoints(scratch_.data(), arm_n, options_.arm_points, rng, arm);
}

}  // namespace twinforge::reality
