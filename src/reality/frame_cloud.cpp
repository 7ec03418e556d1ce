#include "reality/frame_cloud.h"

#include <algorithm>

namespace twinforge::reality {

std::vector<float> DepthMetres(const RgbdFrame& frame) {
  std::vector<float> depth(frame.depth.size());
  for (std::size_t i = 0; i < depth.size(); ++i) depth[i] = frame.depth[i] * 1e-3f;
  return depth;
}

FrameCloud::FrameCloud(const sim::RobotSpec& robot, const sim::WorkspaceSpec& workspace,
                       const Options& options)
    : options_(options),
      workspace_(sim::MakeWorkspace(workspace)),
      model_(sim::LoadModel(robot.mjcf_path())),
      data_(sim::MakeData(model_.get())),
      index_(sim::RobotIndex::Resolve(model_.get(), robot)),
      arm_sampler_(model_.get(), 1u << sim::kRobotGeomGroup) {
  scratch_.resize(3 * std::size_t(arm_sampler_.capacity()));
}

FrameCloud::~FrameCloud() = default;

void FrameCloud::Pose(const Observation& o) {
  mjData* d = data_.get();
  for (int k = 0; k < sim::kArmDof; ++k) d->qpos[index_.arm_qpos[k]] = o.q[k];
  for (int k = 0; k < 2; ++k) d->qpos[index_.finger_qpos[k]] = 0.5 * o.gripper_width;
  mj_kinematics(model_.get(), d);
}

int FrameCloud::RemoveArm(const Observation& observation, const sim::Camera& camera,
                          std::vector<float>& depth) {
  const auto& k = camera.intrinsics;
  if (!caster_ || caster_->camera().intrinsics != k)
    caster_ = std::make_unique<sim::RayCaster>(camera, model_.get());
  caster_->set_pose(camera.pose);
  Pose(observation);
  arm_depth_.resize(depth.size());
  caster_->Render(model_.get(), data_.get(), core::Pose{}, arm_depth_.data(), nullptr, true);
  int removed = 0;
  for (std::size_t i = 0; i < depth.size(); ++i) {
    if (arm_depth_[i] <= 0 || depth[i] <= 0) continue;
    if (depth[i] > arm_depth_[i] - options_.arm_margin) {
      depth[i] = 0;
      ++removed;
    }
  }
  return removed;
}

void FrameCloud::Make(const Observation& observation, const RgbdFrame& frame, core::Rng& rng,
                      float* scene, float* arm) {
  const sim::Camera camera{frame.intrinsics, frame.extrinsics};
  depth_ = DepthMetres(frame);
  RemoveArm(observation, camera, depth_);
  scratch_.resize(std::max(scratch_.size(), 3 * depth_.size()));
  const int n = sim::DepthToPoints(camera, depth_.data(), workspace_, scratch_.data());
  sim::ResamplePoints(scratch_.data(), n, options_.scene_points, rng, scene);
  const int arm_n =
      arm_sampler_.Transform(model_.get(), data_.get(), core::Pose{}, workspace_, scratch_.data());
  sim::ResamplePoints(scratch_.data(), arm_n, options_.arm_points, rng, arm);
}

}  // namespace twinforge::reality
