// SAM-RL's active camera: a camera on a pan/tilt orbit around the workspace whose pose is chosen,
// before the actor acts, to maximize a score of the view it would see (the sensing-aware
// Q-function of that view and the actor's action). The view is rendered by the differentiable
// soft rasterizer, so the pose is found by gradient ascent on the score through the renderer;
// sampling poses and keeping the best is the option that needs no gradients.
//
// Includes <torch/torch.h>: include it only from .cpp files and tests.
#pragma once

#include <torch/torch.h>

#include <Eigen/Dense>
#include <functional>
#include <vector>

#include "core/pinhole.h"
#include "core/rng.h"
#include "core/se3.h"
#include "real2sim/calibrate/soft_render.h"
#include "real2sim/calibrate/twin_geometry.h"
#include "samrl/twin_actor.h"

namespace twinforge::samrl {

// A camera at `radius` from `center`, at an azimuth (about +z, from +x) and an elevation (above
// the xy plane) within limits, looking at the centre with the image's up toward +z.
struct OrbitMount {
  Eigen::Vector3d center = Eigen::Vector3d(0.5, 0.0, 0.1);
  double radius = 0.8;
  double min_azimuth = -M_PI, max_azimuth = M_PI;
  double min_elevation = 0.2, max_elevation = 1.4;
};

// Camera (OpenCV axes) -> base pose for `angles` = [azimuth, elevation] (a [2] double tensor):
// differentiable in the angles.
real2sim::CameraTensor OrbitPose(const OrbitMount& mount, const torch::Tensor& angles);
core::Pose OrbitPose(const OrbitMount& mount, double azimuth, double elevation);

// A score of a rendered view, a differentiable scalar (e.g. Q(view, action)).
using ViewScore = std::function<torch::Tensor(const real2sim::SoftImage&)>;

struct ViewSearchOptions {
  int steps = 60;               // gradient ascent: Adam steps
  double learning_rate = 0.05;  // rad
  int samples = 64;             // sampling: poses drawn uniformly within the limits
  real2sim::SoftRasterOptions raster;
};

struct ViewChoice {
  double azimuth = 0, elevation = 0;
  double score = 0;
  std::vector<double> scores;  // per ascent step or per sample
};

// The twin posed at arm joints `q`, the geoms of `target_bodies` red and the rest blue, and the
// score that counts the red: the percentage of a view the targets fill. A view score for "where
// must the camera be to see the hole" that needs no learning. Throws core::Error naming a body
// the twin does not have.
struct TargetView {
  real2sim::RasterMesh mesh;
  ViewScore score;
};
TargetView TargetVisibility(real2sim::TwinGeometry& twin, const std::array<double, 7>& q,
                            double gripper_width, const std::vector<std::string>& target_bodies);

// Gradient ascent on `score` from (azimuth, elevation), the angles kept within the mount's
// limits. Returns the best pose visited.
ViewChoice AscendView(const real2sim::RasterMesh& scene, const core::PinholeIntrinsics& intrinsics,
                      const OrbitMount& mount, const ViewScore& score, double azimuth,
                      double elevation, const ViewSearchOptions& options = {});

// The best of options.samples poses drawn uniformly within the mount's limits.
ViewChoice SampleView(const real2sim::RasterMesh& scene, const core::PinholeIntrinsics& intrinsics,
                      const OrbitMount& mount, const ViewScore& score, core::Rng& rng,
                      const ViewSearchOptions& options = {});

// Both: the best of options.samples poses, then gradient ascent from it. From a view where the
// score is flat (the target hidden, a learned Q near zero all around), ascent alone has nothing
// to follow; the samples find the slope.
ViewChoice ChooseView(const real2sim::RasterMesh& scene, const core::PinholeIntrinsics& intrinsics,
                      const OrbitMount& mount, const ViewScore& score, core::Rng& rng,
                      const ViewSearchOptions& options = {});

// A mount that looks at a twin's objects: centred on their mean position at the twin's own
// poses, 0.6 m out, at the azimuths and elevations of the task camera's `mount_azimuth` and
// `mount_elevation`. By default from above (elevation 0.8-1.3 rad: a low view sees the table at a
// graze and few of the arm's points the frame is registered by), all round but behind the robot.
OrbitMount ObjectsMount(const sim::Task& twin);

// TargetVisibility with the scene as the twin has it (its objects at home) and the arm at rest:
// what the active look renders at a trial's first look.
TargetView TargetVisibilityAtRest(real2sim::TwinGeometry& twin, const sim::Task& task,
                                  const std::vector<std::string>& targets);

// How the twin actor's looks search (ActiveLook, BestFixedView, a Q's view): 40 x 30 views, the
// best of 24 sampled poses, then 30 ascent steps.
core::PinholeIntrinsics LookSearchCamera();
ViewSearchOptions LookSearch();

// The best fixed camera the twin can propose, the active look's baseline: the mount's view that
// shows `targets` best with the scene as the twin has it and the arm at rest (as ActiveLook
// chooses at a trial's first look, but once, for every look of every trial).
core::Pose BestFixedView(real2sim::TwinGeometry& twin, const sim::Task& task,
                         const std::vector<std::string>& targets, const OrbitMount& mount,
                         const core::PinholeIntrinsics& search,
                         const ViewSearchOptions& options = {}, uint64_t seed = 1);

// The twin as the actor believes the scene is at a look: the arm at joints `q`, the objects where
// it believes them, the `targets` it does not hold red (TargetVisibility), and what earlier frames
// showed in the way (`occluders`) as boxes in the colour of the rest.
TargetView BelievedView(real2sim::TwinGeometry& twin, const std::array<double, 7>& q,
                        double gripper_width,
                        const std::vector<std::pair<std::string, core::Pose>>& objects,
                        const std::string& held, const std::vector<std::string>& targets,
                        const std::vector<Occluder>& occluders = {});

// A score of the views at one look, which may depend on what the actor knows and plans then (a
// sensing-aware Q of the actor's next step).
using LookScore = std::function<ViewScore(const LookContext&)>;

// SAM-RL's active look: at each look the view that shows `targets` best in the twin as the actor
// believes it, around what earlier frames showed in the way (BelievedView with the context's
// occluders; ChooseView on its TargetVisibility, searched at `search`
// intrinsics), then one frame from there with the robot's movable camera at `capture`
// intrinsics. With `score` set (a sensing-aware Q, QLookScore), the view is the one it scores
// best instead, on the same target-coloured render.
Look ActiveLook(reality::Robot& robot, real2sim::TwinGeometry& twin,
                const std::vector<std::string>& targets, const OrbitMount& mount,
                const core::PinholeIntrinsics& search, const core::PinholeIntrinsics& capture,
                const ViewSearchOptions& options = {}, uint64_t seed = 1,
                LookScore score = nullptr);

}  // namespace twinforge::samrl
