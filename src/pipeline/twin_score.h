// A grader for `twin build`: how far a rebuilt twin is from the proxy world it was scanned from.
// It reads the hidden world, so no pipeline stage may call it (`twinforge twin score` only).
//
// The world is taken as it starts (its first reset), which is what a scan taken right after
// `reality serve` started saw. Per task object (the world task's `objects`), against the twin's
// part of the same name with every part jointed to it:
//  - accuracy: mean distance from the twin's surface to the world's full surface;
//  - completeness: mean distance from the world's surface the scan views could see to the twin's;
//    both to the other's triangles, exactly (until stop 32 they went to samples of the other
//    surface, 5 mm apart, which added ~2.5 mm to every twin's score and hid most of its error);
//  - chamfer: the mean of the two (a twin cannot know what no view saw, so the first direction
//    goes to the full surface and the second comes from the visible one);
//  - pose: the rigid motion (ICP) that best moves the twin's surface onto the world's: how far it
//    moves the twin's centre, and by what angle it turns it; and the same for its fitted solids.
// Per task joint: the angle between the axes (opening directions), the upper limit's error, and
// for a hinge the distance of the twin's axis from the world's. Per twin site that the world
// also has: the offset between the two (informative; not a target).
#pragma once

#include <array>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace twinforge::pipeline {

struct TwinScoreOptions {
  int render_width = 160;  // px of the visibility renders (scan intrinsics scaled down)
  // Surface samples per square metre (the twin's, whose distances to the world's triangles are
  // measured, and the world's, for the pose's ICP).
  double density = 250000;
  double chamfer_mm = 5;  // targets, reported as pass / fail
  double axis_deg = 3;
};

struct ObjectScore {
  std::string name;
  bool found = false;  // the twin has a part of this name
  double accuracy_mm = 0, completeness_mm = 0, chamfer_mm = 0;
  double position_mm = 0, rotation_deg = 0;
  // The pose error's parts: the centre's shift (twin -> world, base frame) and how far the turn
  // tips the twin's up axis (the rest of `rotation_deg` is a turn about the vertical).
  std::array<double, 3> shift_mm{0, 0, 0};
  double tilt_deg = 0;
  // The same for what the physics moves, where the part collides as solids fitted to its scan
  // (or drawn): a blurred scan of a 2 cm square peg turns under ICP where its fitted box does
  // not. Zero: the twin collides as its scan.
  double solid_position_mm = 0, solid_rotation_deg = 0;
};

struct JointScore {
  std::string name;
  bool found = false;
  std::string type, twin_type;
  double axis_deg = 0;
  std::array<double, 3> axis{0, 0, 0}, twin_axis{0, 0, 0};  // base frame
  double limit_error = 0;                                   // m or rad
  double origin_mm = 0;  // hinges: the twin axis's point from the world's axis line
};

// A site of the twin against the world's site of the same name (where the task's steps aim).
struct SiteScore {
  std::string name;
  bool found = false;
  std::array<double, 3> error_mm{0, 0, 0};  // twin - world, base frame
  double distance_mm = 0;
};

struct TwinScore {
  std::vector<ObjectScore> objects;
  std::vector<JointScore> joints;
  std::vector<SiteScore> sites;
  double mean_chamfer_mm = 0, max_axis_deg = 0;
  bool pass = false;  // everything found, mean chamfer and every axis within the targets
  nlohmann::json ToJson() const;
};

TwinScore ScoreTwin(const std::filesystem::path& twin_dir, const std::filesystem::path& world_dir,
                    const TwinScoreOptions& options = {});

}  // namespace twinforge::pipeline
