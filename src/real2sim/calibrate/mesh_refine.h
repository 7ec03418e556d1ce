// Refining a twin's scanned meshes against real frames through the differentiable renderer:
// every vertex moves along its normal by its own offset, smoothed by a Laplacian penalty, and
// gets its own colour, so that the twin rendered from each frame's camera shows the depth and the
// colours the real camera saw.
//
// A fused scan is close, not right: the TSDF blurs corners and thin walls, decimation cuts across
// curves, the colours are averages of many views. Here each frame is rendered with the soft
// rasterizer (soft_render.h) and the offsets and colours follow the gradient of a Huber depth
// error and an L1 colour error (Adam), over the pixels that show the refined meshes and agree
// with the real depth to within `outlier` (a pixel off by more is something the twin lacks, or a
// surface the scan never saw). What else a frame shows (the arm, the table) is rendered too,
// fixed, so that it hides what it hides.
//
// Includes <torch/torch.h>: include it only from the calibrate module's .cpp files and tests.
#pragma once

#include <torch/torch.h>

#include <nlohmann/json.hpp>
#include <vector>

#include "core/pinhole.h"
#include "core/progress.h"
#include "core/se3.h"
#include "real2sim/calibrate/calibrate.h"
#include "real2sim/calibrate/soft_render.h"
#include "real2sim/mesh.h"

namespace twinforge::real2sim {

// One real frame to refine against, at the resolution it is rendered at.
struct RefineView {
  core::PinholeIntrinsics intrinsics;
  core::Pose camera_to_base;  // OpenCV axes
  torch::Tensor depth;        // [H, W] double, m, 0 = no return
  torch::Tensor rgb;          // [H, W, 3] double in [0, 1]
  RasterMesh fixed;           // what else it shows, not refined (base frame; may be undefined)
  int64_t table_from = -1;    // fixed's vertices from this one on are the table's (-1: none)
};

// A frame reduced `factor` times in each direction: the median of each block's depth returns
// (none when fewer than half of its pixels returned), the mean of its colours. depth_mm and rgb
// are row-major at `intrinsics`; the view's intrinsics are scaled to match.
RefineView ReduceFrame(const core::PinholeIntrinsics& intrinsics, const core::Pose& camera_to_base,
                       const std::vector<float>& depth_m, const std::vector<uint8_t>& rgb,
                       int factor);

// `views` with the table (RefineView::table_from) raised by `lift` m.
std::vector<RefineView> LiftTable(const std::vector<RefineView>& views, double lift);

// Refines `meshes` (base frame; colours are kept as the start where present, else grey) against
// `views`. Deterministic. Throws ConfigError when no view shows any of the meshes.
MeshRefinement RefineMeshes(const std::vector<Mesh>& meshes, const std::vector<RefineView>& views,
                            const MeshRefineOptions& options, core::Progress* progress = nullptr);

// Places `objects` (base frame, each as it is, no offsets) on the table against `views`, seen
// from the poses the views give (no frame is corrected): each object's one shift along x and y
// and one turn about the upright through its centroid (options.object_pose_*; the frames' and
// shape's options are not used). The result's object_corrections are the motions, its meshes the
// moved objects. Deterministic. Throws ConfigError when no view shows any of them.
MeshRefinement PlaceObjects(const std::vector<Mesh>& objects, const std::vector<RefineView>& views,
                            const MeshRefineOptions& options, core::Progress* progress = nullptr);

// Unit vertex normals: the area-weighted mean of the normals of the triangles around each vertex
// (by their winding); zero for a vertex no triangle uses.
std::vector<Eigen::Vector3d> VertexNormals(const Mesh& mesh);

}  // namespace twinforge::real2sim
