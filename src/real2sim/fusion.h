// Fusion: the frames of a scan (core/scan.h) integrated into one coloured surface (TSDF, Open3D),
// with the robot cut out of every frame by forward kinematics at the joints it was scanned with,
// and the support plane (the table) found in it.
#pragma once

#include <cstdint>

#include "core/progress.h"
#include "core/scan.h"
#include "real2sim/mesh.h"
#include "sim/robot.h"

namespace twinforge::real2sim {

struct FusionOptions {
  double voxel = 0.004;        // m, TSDF voxel
  double truncation = 0.02;    // m, signed-distance truncation
  double depth_max = 2.0;      // m, farther depth is ignored
  double robot_margin = 0.03;  // m, depth this close to the posed robot is the robot
  bool remove_robot = true;
  // Only this box (robot base frame) is kept of the fused surface.
  Eigen::Vector3d crop_min{-0.5, -1.2, -0.2}, crop_max{1.6, 1.2, 1.5};
  uint64_t seed = 1;  // RANSAC for the support plane
};

struct Fusion {
  Mesh mesh;                            // fused surface, cropped
  std::vector<Eigen::Vector3d> points;  // the TSDF's surface points, cropped
  std::vector<Eigen::Vector3d> colors;  // one per point
  Plane support;                        // the dominant near-horizontal plane, normal up
  long robot_pixels = 0;                // depth pixels cut out as the robot
};

// Fuses every frame of `scan`. `robot` describes the arm the scan's joints belong to.
Fusion FuseScan(const core::Scan& scan, const sim::RobotSpec& robot, const FusionOptions& options,
                core::Progress* progress = nullptr);

// A frame's depth in metres (0 = none), checked against the frame's size. Throws IoError.
std::vector<float> ReadDepthMetres(const core::Scan& scan, const core::ScanFrameInfo& frame);

// What a scan saw through: a point is in seen free space when at least `min_frames` frames
// measured something farther than it (by more than `margin`) along their ray through it. Tells
// a part that moved into empty space from a surface a moved part uncovered.
class FreeSpace {
 public:
  explicit FreeSpace(const core::Scan& scan, double margin = 0.015, int min_frames = 2);
  bool SeenThrough(const Eigen::Vector3d& p) const;

 private:
  struct View {
    core::PinholeIntrinsics k;
    core::Pose base_to_camera;
    std::vector<float> depth;
  };
  std::vector<View> views_;
  double margin_;
  int min_frames_;
};

// RANSAC for the plane with the most points within `tolerance` whose normal is within
// `max_tilt` (rad) of +z, refined by least squares on its inliers. Deterministic for a seed.
Plane FitSupportPlane(const std::vector<Eigen::Vector3d>& points, double tolerance, double max_tilt,
                      uint64_t seed, int iterations = 500);

}  // namespace twinforge::real2sim
