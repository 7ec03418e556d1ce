// MJCF export of a twin spec: one body per part (nested along the joints), the part's mesh as a
// visual geom, and collision that respects concavity. MuJoCo collides a mesh as its convex hull,
// which would fill a drawer or a shelf, so each part's surface is voxelized in its own upright
// frame and the voxels are merged greedily into boxes (a few dozen per part).
#pragma once

#include <filesystem>
#include <map>
#include <string>

#include "real2sim/twin_spec.h"

namespace twinforge::real2sim {

// A camera of the scene: where a scan frame (or the task's camera) was, OpenCV axes -> base.
struct ExportCamera {
  std::string name;
  core::Pose pose;
  double fovy_deg = 58;
};

struct ExportOptions {
  double collision_voxel = 0.004;     // m, the boxes' grid: finer than the gaps parts slide in
  int max_boxes = 128;                // per part; the grid coarsens until the part fits, ...
  double max_collision_voxel = 0.01;  // ... up to this, then the smallest boxes are dropped
  double table_thickness = 0.02;      // m, the static table under the support plane
  std::array<double, 2> table_half{0.75, 0.85};  // m, table half-extents (x, y) ...
  std::array<double, 2> table_centre{0.45, 0};   // ... and centre, robot base frame
  std::vector<ExportCamera> cameras;             // written as fixed cameras of the world
};

struct ExportReport {
  std::filesystem::path scene;          // the scene MJCF written
  std::map<std::string, int> boxes;     // collision boxes per part
  std::map<std::string, double> voxel;  // grid each part ended up on
};

// Writes `twin_dir/scene.xml` (a scene file in the format of assets/tasks/*/scene.xml, to be
// assembled with the robot by the sim) and its meshes under `twin_dir/meshes/visual/`.
ExportReport ExportMjcf(const TwinSpec& spec, const std::filesystem::path& twin_dir,
                        const ExportOptions& options = {});

// An axis-aligned box in some frame: centre and half sizes.
struct AlignedBox {
  Eigen::Vector3d centre, half;
};
// Thin boxes covering a surface given as points with outward normals, all in one frame. Points
// are grouped by the axis and sign their normal is nearest to (so a panel's top face and the
// side resting on it never share a box); each group is voxelized and its voxels merged greedily
// into boxes, each box shrunk to its points and given `thickness` behind the surface (inside
// the solid), so gaps of a few mm between parts stay open.
std::vector<AlignedBox> CoverWithBoxes(const std::vector<Eigen::Vector3d>& points,
                                       const std::vector<Eigen::Vector3d>& normals, double voxel,
                                       double thickness = 0.003);

}  // namespace twinforge::real2sim
