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
#include "real2sim/mesh.h"
#include "sim/task.h"

namespace twinforge::real2sim {

// How `calibrate` refines the scanned meshes (mesh_refine.h).
struct MeshRefineOptions {
  int iterations = 150;     // Adam steps; each renders `frames_per_step` frames
  int frames_per_step = 6;  // frames are taken in turn, the same order every run
  int width = 128;          // px: frames are reduced to this width (block medians)
  // px, the renders' soft edge. Softer edges bias the depth: a sphere's 6 mm bump came back to
  // 0.6 mm at 0.3 px, to 0.13 mm at 0.05 px (mesh_refine_test).
  double sigma = 0.05;
  double learning_rate = 0.2;  // mm of offset per step (Adam)
  double color_learning_rate = 0.01;
  double huber = 2;       // mm, the depth error's Huber width
  double outlier = 10;    // mm: pixels off by more do not count
  double rgb_weight = 1;  // x the mean L1 colour error, against the mean Huber depth error (mm)
  // x the mean squared difference (mm^2) of the offsets of the two ends of each mesh edge: a
  // mesh moves as a surface, not vertex by vertex.
  double smoothness = 4;
  double prior = 0.01;    // x the mean squared offset (mm^2): unseen vertices stay put
  double max_offset = 8;  // mm, in either direction along the normal
  // Each frame's camera pose is corrected too (the hand camera's reported poses are a few mm
  // off, each differently): from every pixel that agrees, the table's and the arm's included.
  bool frame_poses = true;
  double pose_learning_rate = 0.15;  // mrad and mm per step
  double pose_prior = 0.01;          // x the mean squared correction (mrad^2, mm^2)
  // With frame_poses, the table's height too: the twin's table is where the scan's fused surface
  // put it, 0.4-2 mm below the proxy worlds' tables (the frames' own depth puts them within
  // 0.6 mm), and a table at the wrong height draws the frames, and the meshes with them, to it.
  bool table_height = true;
  // Then each object is placed on the table (RefineTwinMeshes, PlaceObjects), since where the
  // scan put it is off by a few mm and degrees: one shift along the table and one turn about the
  // upright through its centroid, shared by every frame, each frame seen from where it was
  // corrected to. An object is its refined mesh, or the solids its parts collide with where they
  // collide as solids and show it as its mesh does (a peg and its hole, fitted to the scan's
  // blur; not a mug's cylinder, without its handle). The turn is counted in mm at the object's
  // rms radius about that line, so that one rate and one prior serve both.
  bool object_poses = true;
  double object_pose_learning_rate = 0.1;  // mm per step
  double object_pose_prior = 0.01;         // x the mean squared correction (mm^2)
  // An object keeps the pose the scan gave it unless its placement lowers the mean depth error
  // over its own pixels by at least this share: a move that buys less is not what the frames
  // tell (placed, the pegs' solids explained their pixels 14-22% better).
  double object_pose_min_gain = 0.1;
  template <class A>
  void Serialize(A& a) {
    a("iterations", iterations);
    a("frames_per_step", frames_per_step);
    a("width", width);
    a("sigma", sigma);
    a("learning_rate", learning_rate);
    a("color_learning_rate", color_learning_rate);
    a("huber", huber);
    a("outlier", outlier);
    a("rgb_weight", rgb_weight);
    a("smoothness", smoothness);
    a("prior", prior);
    a("max_offset", max_offset);
    a("frame_poses", frame_poses);
    a("pose_learning_rate", pose_learning_rate);
    a("pose_prior", pose_prior);
    a("table_height", table_height);
    a("object_poses", object_poses);
    a("object_pose_learning_rate", object_pose_learning_rate);
    a("object_pose_prior", object_pose_prior);
    a("object_pose_min_gain", object_pose_min_gain);
    a.Require(iterations >= 0, "iterations", "zero (no refinement) or more steps");
    a.Require(frames_per_step >= 1, "frames_per_step", "at least one frame");
    a.Require(width >= 16, "width", "at least 16 px");
    a.Require(sigma > 0, "sigma", "a positive width in px");
    a.Require(learning_rate > 0 && color_learning_rate >= 0, "learning_rate",
              "a positive step (mm)");
    a.Require(huber > 0 && outlier > huber, "outlier", "a distance (mm) above the Huber width");
    a.Require(rgb_weight >= 0 && smoothness >= 0 && prior >= 0, "smoothness",
              "non-negative weights");
    a.Require(max_offset > 0, "max_offset", "a positive distance in mm");
    a.Require(pose_learning_rate > 0 && pose_prior >= 0, "pose_learning_rate",
              "a positive step and a non-negative prior");
    a.Require(object_pose_learning_rate > 0 && object_pose_prior >= 0, "object_pose_learning_rate",
              "a positive step (mm) and a non-negative prior");
    a.Require(object_pose_min_gain >= 0 && object_pose_min_gain < 1, "object_pose_min_gain",
              "a share from 0 (any gain) to under 1");
  }
};

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
  MeshRefineOptions mesh;  // the scanned meshes against the scan's frames (iterations 0: off)
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
    a("mesh", mesh);
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

struct MeshRefinement {
  std::vector<Mesh> meshes;  // the refined meshes, in the order given, with vertex colours
  std::vector<double> loss;  // per step
  // Over every view, pixels showing the refined meshes within the outlier distance:
  double depth_error_before = 0, depth_error_after = 0;  // mm, mean absolute
  double rgb_error_before = 0, rgb_error_after = 0;      // mean absolute, 0..1
  double inliers_before = 0, inliers_after = 0;          // share of those pixels within outlier
  double offset_rms = 0, offset_max = 0;                 // mm
  std::vector<core::Pose> frame_corrections;  // per view: true pose = reported * correction
  double table_lift_mm = 0;  // how far above the twin's table the frames put it (table_height)
  // Per mesh, the motion PlaceObjects found for it (base frame; none from RefineMeshes): the
  // placed vertices are the correction applied to the refined ones.
  std::vector<core::Pose> object_corrections;
  std::vector<Eigen::Vector3d> object_centroids;  // per mesh, what it turned about (m)
  // Per mesh, the mean depth error over its own pixels at its start and placed (mm), and whether
  // the placement was kept (object_pose_min_gain).
  std::vector<double> object_errors_before, object_errors_after;
  std::vector<bool> object_placed;
  double seconds = 0;
  nlohmann::json ToJson() const;
};

// Refines the scanned meshes of the twin in `twin_dir` (the files its twin.yaml parts name)
// against the frames of `scan` (the scan the twin was built from: its wrist-camera poses are the
// robot's own), each frame reduced to `options.width` and shown with the arm at its joints and
// the table. With options.object_poses each object is then placed (PlaceObjects): its mesh and
// what twin.yaml places with it (cuts, solids, sites, joint) move with it, and twin.yaml is
// rewritten (the old one kept as twin.yaml.bak). Rewrites the mesh files, re-exports scene.xml
// (the visual meshes and the scan-fitted collision boxes follow the new surfaces) and writes
// twin_dir/calibration/mesh.json with
// mesh_NN.png per frame (real | twin before | after | depth error before | after). Throws
// ConfigError when the twin has no scanned mesh or no frame shows one.
MeshRefinement RefineTwinMeshes(const std::filesystem::path& twin_dir, const core::Scan& scan,
                                const MeshRefineOptions& options,
                                core::Progress* progress = nullptr);

}  // namespace twinforge::real2sim
