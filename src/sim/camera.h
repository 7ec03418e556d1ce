// Cameras and point clouds in the robot base frame.
//
// Two ways to get a scene cloud: (a) synthetic, points sampled on the geometry at its current
// pose (cheap, no occlusion); (b) rendered, a depth image ray-cast from a pinhole camera, with
// optional depth noise, back-projected and cropped to the workspace. The arm's own points always
// come from forward kinematics (its geoms sampled at their current poses), never from depth.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <vector>

#include "core/pinhole.h"
#include "core/rng.h"
#include "core/se3.h"
#include "sim/geom_scene.h"
#include "sim/model.h"
#include "sim/task.h"

namespace twinforge::sim {

using CameraIntrinsics = core::PinholeIntrinsics;

// A pinhole camera; `pose` maps camera coordinates (OpenCV: x right, y down, z forward) to the
// robot base frame.
struct Camera {
  CameraIntrinsics intrinsics;
  core::Pose pose;
};

// The task's camera: intrinsics from its field of view, pose looking from `position` at `look_at`,
// then moved by its calibration's correction.
Camera MakeCamera(const CameraSpec& spec);
// A calibration correction ([rx, ry, rz, x, y, z], camera frame) as a pose, and back.
core::Pose CorrectionPose(const std::array<double, 6>& correction);
std::array<double, 6> CorrectionArray(const core::Pose& correction);

struct Workspace {
  Eigen::Vector3f min, max;
  bool Contains(const float* p) const {
    return p[0] >= min[0] && p[0] <= max[0] && p[1] >= min[1] && p[1] <= max[1] && p[2] >= min[2] &&
           p[2] <= max[2];
  }
};
Workspace MakeWorkspace(const WorkspaceSpec& spec);

// Geom groups seen by cameras and samplers. The robot's geoms are in group 1.
constexpr int kRobotGeomGroup = 1;

// Ray-casts depth (metres along the optical axis, 0 = no return) and RGB images of a model's
// geoms (through an Embree scene built once from `m`; see sim/geom_scene.h).
class RayCaster {
 public:
  RayCaster(const Camera& camera, const mjModel* m);
  // Renders into depth[width*height] and, if not null, rgb[width*height*3] and geom[width*height]
  // (the geom seen, -1 for none). `base` is the robot base pose in the world. Robot geoms are
  // skipped unless `include_robot`. Allocation-free. `m` must have the layout of the
  // constructor's model (its sizes and colours may differ).
  void Render(const mjModel* m, const mjData* d, const core::Pose& base, float* depth, uint8_t* rgb,
              bool include_robot = false, int* geom = nullptr);
  const Camera& camera() const { return camera_; }
  // Moves the camera (same intrinsics): a scan camera, or a pose being calibrated.
  void set_pose(const core::Pose& pose) { camera_.pose = pose; }
  GeomScene& scene() { return scene_; }

 private:
  Camera camera_;
  GeomScene scene_;
  std::vector<double> directions_;  // unit ray per pixel, camera frame (3 per pixel)
  std::vector<double> z_scale_;     // optical-axis component of each ray
};

// The edges of a width x height depth image (0 = no return): pixels with a return that have a
// 4-neighbour with none, or one nearer or farther by more than `jump` m. Every depth sensor here
// (the twin's noise model, its estimate from real frames, the proxy's hidden sensor) loses
// returns at these pixels.
std::vector<uint8_t> DepthEdges(const float* depth, int width, int height, double jump);

// Applies a sensor's noise (DepthNoise, in sim/task.h) to a width x height depth image in place:
// edge pixels (found on the image as given) and others lose their return with their
// probabilities; with `geom` (the geom each pixel sees, -1 for none), a return that survived is
// then lost with its geom's `surface_dropout` (indexed by geom id; SurfaceDropoutByGeom). The
// returns left get Gaussian noise and are quantized. Pixels with no return stay 0. Draws
// nothing from `rng` when the noise is off.
void AddDepthNoise(float* depth, int width, int height, const DepthNoise& noise, core::Rng& rng,
                   const int* geom = nullptr, const std::vector<double>& surface_dropout = {});

// The noise's surface dropouts indexed by `m`'s geom ids (0 for the other geoms); empty when it
// has none. Throws ConfigError naming a surface geom `m` does not have.
std::vector<double> SurfaceDropoutByGeom(const mjModel* m, const DepthNoise& noise);

// Back-projects a depth image into base-frame points inside `workspace`; writes up to
// width*height points to xyz and returns how many.
int DepthToPoints(const Camera& camera, const float* depth, const Workspace& workspace, float* xyz);

// Points on the surfaces of a set of geoms, precomputed once in each geom's frame and moved to
// the geoms' current poses on demand.
class SurfaceSampler {
 public:
  // Samples the geoms whose group is in `groups` (bit i = group i), area-weighted at `density`
  // points per square metre, between `min_per_geom` and `max_per_geom` points each; with
  // `keep`, only the geoms it accepts.
  SurfaceSampler(const mjModel* m, unsigned groups, double density = 20000, int min_per_geom = 16,
                 int max_per_geom = 4000, const std::function<bool(int)>& keep = nullptr);

  // Writes the base-frame points inside `workspace` to xyz (capacity: capacity() points) and
  // returns how many. Primitive sizes are read from the model, so resized geoms stay right.
  int Transform(const mjModel* m, const mjData* d, const core::Pose& base,
                const Workspace& workspace, float* xyz) const;
  int capacity() const { return static_cast<int>(geom_.size()); }

 private:
  std::vector<int> geom_;        // geom id of each sample
  std::vector<float> local_;     // sample in the geom frame, as a fraction of its size for
                                 // primitives, or in metres for meshes (3 per sample)
  std::vector<uint8_t> scaled_;  // whether local_ is relative to geom_size
};

// Draws exactly `count` points from `points` (n of them, `stride` floats each) into out, without
// replacement when n >= count (keeping their order), otherwise all of them plus repeats;
// zero-fills when n == 0.
void ResamplePoints(const float* points, int n, int count, core::Rng& rng, float* out,
                    int stride = 3);

class RobotMask;

// What a real frame loses to the arm (reality::FrameCloud, sim::RobotMask::Remove): the arm's
// silhouette grown by this many pixels, and there everything behind the arm or less than this
// margin in front of it.
constexpr double kArmDepthMargin = 0.03;  // m
constexpr int kArmGrowPixels = 2;

// Everything needed to turn an env's state into the clouds a policy sees, with buffers
// allocated once: the same two clouds reality::FrameCloud makes from a real frame. Not
// thread-safe: one per worker.
class CloudMaker {
 public:
  struct Options {
    int scene_points = 6000;
    int arm_points = 3000;
    // Ray-cast depth of the scene (else synthetic samples on its surfaces). As on a real frame,
    // the sensor's noise is applied and the arm's pixels are cut out (the arm hides what is
    // behind it and the cut takes a margin around it), so the gripper's surroundings look as
    // they do on the robot.
    bool rendered = true;
    DepthNoise noise;
  };
  CloudMaker(const Task& task, const mjModel* m, const Options& options);
  ~CloudMaker();

  // Fills scene[scene_points*3] and arm[arm_points*3] (base frame, workspace-cropped).
  void Make(const mjModel* m, const mjData* d, const core::Pose& base, core::Rng& rng, float* scene,
            float* arm);
  const Options& options() const { return options_; }
  RayCaster& caster() { return caster_; }

 private:
  Options options_;
  Workspace workspace_;
  RayCaster caster_;
  SurfaceSampler scene_sampler_, arm_sampler_;
  RobotIndex robot_;                     // in the env's model
  std::unique_ptr<RobotMask> mask_;      // the robot alone, to cut out of rendered depth
  std::vector<double> surface_dropout_;  // by geom id (empty: no surface loses more)
  std::vector<float> depth_, scratch_;
  std::vector<int> geom_;  // the geom each pixel sees, when surfaces have their own dropout
};

}  // namespace twinforge::sim
