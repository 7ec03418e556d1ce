// A known object's drawing, and where a scan shows it. Some objects a depth scan cannot rebuild:
// a spatula's 3 mm blade lying on the table is the table to the sensor. A tool is a known
// object, though, with a drawing (its CAD, here one body of an MJCF file). The twin takes its
// shape, mass and named points from the drawing and only its pose from the scan: ICP of the
// drawing onto what the scan saw of it (the handle), the drawing resting on the table as drawn.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "real2sim/mesh.h"
#include "real2sim/twin_spec.h"

namespace twinforge::real2sim {

struct Drawing {
  std::string body;                               // the drawn body's name
  std::vector<BoxSpec> solids;                    // its geoms (boxes and cylinders), in its frame
  std::vector<Eigen::Vector3d> colours;           // one per solid, 0..1
  double mass = 0;                                // kg
  Eigen::Vector3d com = Eigen::Vector3d::Zero();  // centre of mass, its frame
  struct Point {
    std::string name;
    Eigen::Vector3d at;
  };
  std::vector<Point> sites;  // its named points (sites), its frame

  // The solids' closed surfaces, coloured, in its frame.
  Mesh Surface() const;
  // How far its lowest point is below its frame's origin (m, positive).
  double Depth() const;
};

// Reads body `body` of the MJCF file `mjcf`: its box and cylinder geoms (as MuJoCo compiled
// them, relative to the body), its mass and centre of mass, its sites. Throws core::IoError for
// a missing file, core::ConfigError naming the file for a body it lacks or a geom of another
// type.
Drawing ReadDrawing(const std::filesystem::path& mjcf, const std::string& body);

struct DrawingFit {
  core::Pose pose;      // drawing frame -> base: upright, resting on the support
  double rms = 0;       // m: the scan's points to the posed drawing's surface (each cut at 2 cm)
  double coverage = 0;  // of the drawing's surface at the heights the scan saw, the share within
                        // 5 mm of a scanned point
  int candidates = 0;   // start poses tried
};

// The pose of `drawing`, resting upright on `support`, that best explains `points` (a scan's
// segment; it may show only part of the object: a lost blade, a hidden side). From start yaws
// every 10 degrees, each with what the drawing shows above the scan's lowest point centred on
// the points, point-to-plane ICP of the points onto the drawing's surface; then the turn about
// the vertical and the table height kept. The best by distance both ways (points to drawing,
// drawing's visible part to points) wins. Throws core::Error for an empty segment.
DrawingFit PoseDrawing(const Drawing& drawing, const std::vector<Eigen::Vector3d>& points,
                       const Plane& support);

}  // namespace twinforge::real2sim
