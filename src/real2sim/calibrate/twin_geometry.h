// The twin as triangles for the soft rasterizer: its visible geoms (robot and scene) tessellated
// once in their own frames, scanned meshes decimated so that a frame renders in milliseconds,
// then posed for a robot configuration. Calibration compares real frames with it; SAM-RL's active
// camera scores views of it.
//
// Includes <torch/torch.h>: include it only from .cpp files and tests.
#pragma once

#include <Eigen/Dense>
#include <array>
#include <functional>
#include <memory>
#include <vector>

#include "real2sim/calibrate/soft_render.h"
#include "real2sim/mesh.h"
#include "sim/camera.h"
#include "sim/env.h"
#include "sim/task.h"

namespace twinforge::real2sim {

class TwinGeometry {
 public:
  // Throws ConfigError naming the task file when its scene has no visible geom.
  TwinGeometry(const sim::TaskSpec& spec, int mesh_triangles);

  // A colour per geom id, instead of the model's.
  using GeomColor = std::function<Eigen::Vector3d(int geom)>;

  // The twin with the arm at `q`, the fingers `gripper_width` apart and the scene at its
  // nominal state, in the robot base frame; with `keep`, only the geoms it accepts.
  RasterMesh Posed(const std::array<double, 7>& q, double gripper_width,
                   const GeomColor& color = nullptr,
                   const std::function<bool(int geom)>& keep = nullptr);

  // The twin ray-cast from `camera` (robot included, arm at `q`): depth (m along the optical
  // axis, 0 = no return) and the geom each pixel sees (-1 = none), width x height of its
  // intrinsics.
  void RayCast(const std::array<double, 7>& q, double gripper_width, const sim::Camera& camera,
               std::vector<float>* depth, std::vector<int>* geom);

  // Puts a movable body (one with a free joint) at `pose` (robot base frame) for every later
  // Posed and RayCast. Throws core::Error for a body without a free joint.
  void PlaceBody(int body, const core::Pose& pose) { env_.PlaceBody(body, pose); }

  const mjModel* model() const { return env_.model(); }

 private:
  void PoseArm(const std::array<double, 7>& q, double gripper_width);

  struct Piece {
    int geom = -1;
    Mesh mesh;  // geom frame, scaled
    Eigen::Vector3d color;
  };
  std::shared_ptr<const sim::Task> task_;
  sim::Env env_;
  std::vector<Piece> pieces_;
};

}  // namespace twinforge::real2sim
