#include "sim/robot_mask.h"

namespace twinforge::sim {

RobotMask::RobotMask(const RobotSpec& spec)
    : model_(LoadModel(spec.mjcf_path())),
      data_(MakeData(model_.get())),
      index_(RobotIndex::Resolve(model_.get(), spec)),
      sampler_(model_.get(), 1u << kRobotGeomGroup) {}

RobotMask::~RobotMask() = default;

void RobotMask::Pose(const ArmVector& q, double gripper_width) {
  mjData* d = data_.get();
  for (int k = 0; k < kArmDof; ++k) d->qpos[index_.arm_qpos[k]] = q[k];
  for (int k = 0; k < 2; ++k) d->qpos[index_.finger_qpos[k]] = 0.5 * gripper_width;
  mj_kinematics(model_.get(), d);
}

int RobotMask::Remove(const Camera& camera, std::vector<float>& depth, double margin, int grow) {
  if (!caster_ || caster_->camera().intrinsics != camera.intrinsics)
    caster_ = std::make_unique<RayCaster>(camera, model_.get());
  caster_->set_pose(camera.pose);
  robot_depth_.resize(depth.size());
  caster_->Render(model_.get(), data_.get(), core::Pose{}, robot_depth_.data(), nullptr, true);
  // Grow the silhouette: each pixel takes the nearest robot depth around it.
  const int w = camera.intrinsics.width, h = camera.intrinsics.height;
  grown_ = robot_depth_;
  if (grow > 0)
    for (int v = 0; v < h; ++v)
      for (int u = 0; u < w; ++u) {
        float nearest = robot_depth_[v * w + u];
        for (int dv = -grow; dv <= grow; ++dv)
          for (int du = -grow; du <= grow; ++du) {
            const int uu = u + du, vv = v + dv;
            if (uu < 0 || vv < 0 || uu >= w || vv >= h) continue;
            const float z = robot_depth_[vv * w + uu];
            if (z > 0 && (nearest <= 0 || z < nearest)) nearest = z;
          }
        grown_[v * w + u] = nearest;
      }
  int removed = 0;
  for (std::size_t i = 0; i < depth.size(); ++i) {
    if (grown_[i] <= 0 || depth[i] <= 0) continue;
    if (depth[i] > grown_[i] - margin) {
      depth[i] = 0;
      ++removed;
    }
  }
  return removed;
}

int RobotMask::Surface(const Workspace& workspace, float* xyz) const {
  return sampler_.Transform(model_.get(), data_.get(), core::Pose{}, workspace, xyz);
}

}  // namespace twinforge::sim
