// RGB-D scans on disk, in the layout Open3D's RGB-D tools read:
//
//   scan/
//     color/000000.png ...   8-bit RGB
//     depth/000000.png ...   16-bit grey, millimetres (depth_scale 1000), 0 = no return
//     intrinsic.json         Open3D PinholeCameraIntrinsic (width, height, intrinsic_matrix
//                            column-major), of frame 0
//     trajectory.json        Open3D PinholeCameraTrajectory: per frame, extrinsic = world ->
//                            camera (column-major 4x4) and its intrinsic; world = robot base
//     trajectory.log         the same poses in Redwood's .log format (camera -> world, rows)
//     frames.json            twinforge's own index: per frame its files, stamp, intrinsics,
//                            camera -> base pose, and the robot's joints when it was taken (so
//                            the robot can be cut out of the scan by forward kinematics)
//
// e.g. o3d.io.read_pinhole_camera_trajectory("scan/trajectory.json") and
// o3d.geometry.RGBDImage.create_from_color_and_depth(..., depth_scale=1000) with
// o3d.pipelines.integration.ScalableTSDFVolume. Every index file is rewritten (atomically) after
// each frame, so an interrupted scan leaves the frames it took, usable.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "core/pinhole.h"
#include "core/se3.h"

namespace twinforge::core {

struct ScanFrameInfo {
  std::string color, depth;  // relative to the scan directory
  double stamp = 0;
  PinholeIntrinsics intrinsics;
  Pose camera_to_base;  // OpenCV camera axes
  std::array<double, 7> joint_positions{};
  double gripper_width = 0;
};

struct Scan {
  std::filesystem::path dir;
  std::string source;  // who took it, e.g. "proxy:open_drawer"
  std::string robot;   // robot description name
  double depth_scale = 1000.0;
  std::vector<ScanFrameInfo> frames;
};

class ScanWriter {
 public:
  // Creates `dir` (refusing a directory that already holds a scan).
  ScanWriter(const std::filesystem::path& dir, std::string source, std::string robot);
  // Writes frame images and rewrites the index files. `rgb` is width*height*3, `depth_mm`
  // width*height.
  void Add(ScanFrameInfo info, const std::vector<uint8_t>& rgb,
           const std::vector<uint16_t>& depth_mm);
  const Scan& scan() const { return scan_; }

 private:
  void WriteIndex() const;
  Scan scan_;
};

// Reads frames.json of a scan directory. Throws IoError / ConfigError naming the file and field.
Scan ReadScan(const std::filesystem::path& dir);

}  // namespace twinforge::core
