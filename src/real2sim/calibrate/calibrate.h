// `twinforge calibrate`: where the real camera really is, found by rendering the twin.
//
// A fixed camera's mount is known only roughly (its calibration says one thing; the bracket got
// bumped). Given a few frames of that camera (RGB-D, the robot's joints when each was taken, the
// extrinsics the robot reports), the twin is rendered from the reported pose with the
// differentiable renderer (soft_render.h): the scene's visible geoms and the arm posed at each
// frame's joints. A correction of the pose, in the camera's own frame, is found by damped
// Gauss-Newton (Levenberg-Marquardt) on the depth residuals, the arm's pixels weighted above the
// scene's: the arm's shape and joints are known exactly, the scene only as well as its scan. (The
// first solver, still an option, followed the gradient of the depth error and of the EMD between
// the real and rendered clouds with Adam; its fixed-size steps drifted along directions the frames
// hardly see.) The same frames also give Open3D's point-to-plane ICP, reported side by side as
// the baseline.
//
// The refined twin is a copy of the twin whose task.yaml camera carries the correction
// (CameraSpec::correction): the sim then renders where the real camera is, and real frames are
// turned into clouds with it (reality::FrameCloud).
#pragma once

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/progress.h"
#include "core/scan.h"
#include "core/se3.h"
#include "sim/task.h"

namespace twinforge::real2sim {

struct CalibrateOptions {
  // "gauss_newton": Levenberg-Marquardt on the depth residuals (Jacobians by differences of
  // renders); "adam": gradient steps on depth + EMD (+ colour) through the soft renderer.
  std::string solver = "gauss_newton";
  int gauss_newton_iterations = 30;  // at most (it stops when a step no longer lowers the loss)
  // px, the renders' soft edge. Wider edges bias the fit: at 0.3 px the mount came out 6-13 mm
  // off on the proxy drawer and mug, at 0.05 px 0.5-1.5 mm (docs/calibrate.md).
  double gauss_newton_sigma = 0.05;
  double arm_weight = 10;                   // x the weight of a scene pixel, for the arm's pixels
  bool start_from_icp = true;               // a second run from ICP's answer; the lower loss wins
  int iterations = 150;                     // Adam steps in all (solver "adam")
  std::vector<double> sigmas = {1.0, 0.5};  // px, the soft edge, coarse to fine
  double learning_rate = 0.003;             // rad and m per step (Adam)
  double depth_weight = 100;                // x mean Huber depth error (m)
  double emd_weight = 10;                   // x Sinkhorn EMD between the clouds (m)
  double rgb_weight = 0;  // x mean colour difference where the real camera has returns
  int emd_points = 400;   // points per cloud and frame for the EMD
  // A weak prior that the camera is near its reported pose (rad and m at which it costs as much as
  // a 1 mm mean depth error): directions the frames cannot tell apart stay where they were.
  double prior_rotation = 0.05;
  double prior_translation = 0.05;
  double outlier = 0.08;  // m: depth differences beyond this are ignored
  // Each geom is decimated to this many triangles to render. Coarser meshes move surfaces by
  // millimetres: at 600, ICP's answer (the second start) was 14-23 mm off on the drawer, 0.3-0.5
  // mm at 3000.
  int mesh_triangles = 3000;
  uint64_t seed = 1;
  // The step budget of the chosen solver.
  int& Steps() { return solver == "adam" ? iterations : gauss_newton_iterations; }
  int Steps() const { return solver == "adam" ? iterations : gauss_newton_iterations; }
  // What a progress bar counts to (Gauss-Newton: per start).
  int ProgressSteps() const {
    return solver == "adam" ? iterations : (start_from_icp ? 2 : 1) * gauss_newton_iterations;
  }
  template <class A>
  void Serialize(A& a) {
    a("solver", solver);
    a("gauss_newton_iterations", gauss_newton_iterations);
    a("gauss_newton_sigma", gauss_newton_sigma);
    a("arm_weight", arm_weight);
    a("start_from_icp", start_from_icp);
    a("iterations", iterations);
    a("sigmas", sigmas);
    a("learning_rate", learning_rate);
    a("depth_weight", depth_weight);
    a("emd_weight", emd_weight);
    a("rgb_weight", rgb_weight);
    a("emd_points", emd_points);
    a("prior_rotation", prior_rotation);
    a("prior_translation", prior_translation);
    a("outlier", outlier);
    a("mesh_triangles", mesh_triangles);
    a("seed", seed);
    a.Require(solver == "gauss_newton" || solver == "adam", "solver",
              "\"gauss_newton\" or \"adam\"");
    a.Require(gauss_newton_iterations >= 1 && iterations >= 1, "iterations", "at least one step");
    a.Require(gauss_newton_sigma > 0, "gauss_newton_sigma", "a positive width in px");
    a.Require(!sigmas.empty(), "sigmas", "at least one edge width");
    for (double s : sigmas) a.Require(s > 0, "sigmas", "positive widths in px");
    a.Require(learning_rate > 0, "learning_rate", "a positive step");
    a.Require(emd_points >= 16, "emd_points", "at least 16 points");
    a.Require(outlier > 0, "outlier", "a positive distance in m");
    a.Require(prior_rotation > 0 && prior_translation > 0, "prior_rotation",
              "positive prior widths (rad, m)");
    a.Require(mesh_triangles >= 100, "mesh_triangles", "at least 100 triangles");
  }
};

// How well the twin, rendered from a pose, explains a frame.
struct FrameFit {
  double median_depth_error = 0;  // m, over pixels both see (within the outlier distance)
  double inliers = 0;             // fraction of the frame's returns within the outlier distance
};

struct CameraCalibration {
  core::Pose correction;      // camera frame: true pose = reported pose * correction
  core::Pose icp_correction;  // the same found by Open3D's point-to-plane ICP (the baseline)
  std::vector<FrameFit> before, after, icp;  // per frame
  std::vector<double> loss;                  // per step
  // The real depth sensor's noise, measured on the frames against the twin from the calibrated
  // pose (returns lost at the twin's depth edges and elsewhere, and the depth's spread). The
  // calibrated twin's camera carries it, so its rendered clouds look like the real ones.
  sim::DepthNoise noise;
  double seconds = 0;
};

// Calibrates the fixed camera that took every frame of `frames` against the twin task (its scene
// and the robot at each frame's joints). Throws ConfigError if a frame cannot be read or shows
// nothing of the twin.
CameraCalibration CalibrateCamera(const sim::TaskSpec& twin_task, const core::Scan& frames,
                                  const CalibrateOptions& options,
                                  core::Progress* progress = nullptr);

nlohmann::json ToJson(const CameraCalibration& calibration);

// How well the twin explains each frame with the camera at its reported pose * `correction`.
std::vector<FrameFit> FitFrames(const sim::TaskSpec& twin_task, const core::Scan& frames,
                                const core::Pose& correction, const CalibrateOptions& options);

// Writes the refined twin: a copy of `twin_dir` in `out` whose task.yaml camera carries the
// calibration (on top of any it had), calibration.json, and before/after images of each frame
// (real | twin before | twin after, colour and depth error) under out/calibration/.
void WriteCalibratedTwin(const std::filesystem::path& twin_dir, const core::Scan& frames,
                         const CameraCalibration& calibration, const CalibrateOptions& options,
                         const std::filesystem::path& out);

}  // namespace twinforge::real2sim
