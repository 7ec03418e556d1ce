// Scanning a scene through the robot: the scan camera is moved through a path of poses around
// the task's workspace and one RGB-D frame is saved at each, in the layout of core/scan.h.
#pragma once

#include <filesystem>
#include <vector>

#include "core/progress.h"
#include "core/scan.h"
#include "reality/robot.h"
#include "reality/teleop.h"
#include "sim/task.h"

namespace twinforge::reality {

struct ScanOptions {
  int width = 640, height = 480;
  double fovy_deg = 58;
  int frames_per_ring = 12;
  std::vector<double> elevations_deg = {25, 50};  // one ring of views per elevation
  double azimuth_span_deg = 200;  // centred on the task camera's direction from the scene
  double radius = 0;              // m from the scene centre; 0: the task camera's distance
  template <class A>
  void Serialize(A& a) {
    a("width", width);
    a("height", height);
    a("fovy_deg", fovy_deg);
    a("frames_per_ring", frames_per_ring);
    a("elevations_deg", elevations_deg);
    a("azimuth_span_deg", azimuth_span_deg);
    a("radius", radius);
    a.Require(width > 0 && height > 0 && width <= 4096 && height <= 4096, "width",
              "an image size in 1..4096");
    a.Require(frames_per_ring >= 1, "frames_per_ring", "at least one frame");
    a.Require(!elevations_deg.empty(), "elevations_deg", "at least one elevation");
    a.Require(radius >= 0, "radius", "a non-negative distance");
  }
};

// Camera poses (camera -> robot base, OpenCV axes) looking at the task camera's look-at point
// from rings around it, and the intrinsics they share.
std::vector<core::Pose> ScanPath(const sim::TaskSpec& task, const ScanOptions& options);
sim::CameraIntrinsics ScanIntrinsics(const ScanOptions& options);

// Takes one frame per pose and writes the scan to `out` (which must not hold a scan yet).
core::Scan CaptureScan(Robot& robot, const std::vector<core::Pose>& path,
                       const sim::CameraIntrinsics& intrinsics, const std::filesystem::path& out,
                       core::Progress* progress = nullptr);

// Frames of the robot's fixed camera for its calibration (`twinforge calibrate`): the first with
// the arm at home, then with the tool held (in its home orientation) at `count - 1` points drawn
// within `spread` m of `centre` (above it only), so that the camera sees the arm, whose shape is
// known exactly, in different places. One frame is saved at each with its reported extrinsics and
// the joints, in the layout of core/scan.h; the arm goes home at the end. Joint targets ramp to
// each pose over a second rather than jump (there is no safety filter for joint targets). The
// scene is not touched.
//
// The defaults hold the tool low (8 cm above where the camera looks) and spread it 25 cm: the arm
// then fills the middle of the view at different depths, which pins the camera's translation
// better than the scene's scan can (16 such frames: 6-10 mm on the drawer world, against 21-35 mm
// with 6 frames 15 cm up and 12 cm apart; docs/calibrate.md).
inline constexpr int kCameraFrames = 16;
inline constexpr double kCameraFramesHeight = 0.08;  // m above the camera's look-at point
inline constexpr double kCameraFramesSpread = 0.25;  // m
core::Scan CaptureCameraFrames(Robot& robot, const sim::Kinematics& kinematics,
                               const Eigen::Vector3d& centre, int count, double spread,
                               uint64_t seed, const std::filesystem::path& out,
                               core::Progress* progress = nullptr);

// The scene in a second state, for the articulation estimate (RialTo: scan, open the drawer,
// scan again): the operator drives the robot from where it is, without a reset, until they say
// done (or 3 x the task's horizon); then the arm goes back to its home pose with the gripper
// open, so that it hides as little of the scene as it can. Returns the actions sent.
int OperateThenHome(Robot& robot, Operator& op, const sim::TaskSpec& task);

}  // namespace twinforge::reality
