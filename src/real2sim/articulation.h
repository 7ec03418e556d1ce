// Articulation from observation: given the scene's surface in two states (e.g. the drawer
// closed, then open after a pull), find what moved and how: joint type, axis, a point on the
// axis (revolute), and how far it moved between the two states.
#pragma once

#include <vector>

#include "real2sim/twin_spec.h"

namespace twinforge::real2sim {

struct ArticulationOptions {
  double changed = 0.01;             // m: a point this far from the other state's surface moved
  double max_correspondence = 0.02;  // m, ICP
  double prismatic_below = 3.0 * M_PI / 180;  // rad: smaller rotations are a slide
  // Up to this turn, a slide still wins unless the rigid fit's RMSE is below this share of the
  // slide's (a flat front fits almost as well turned a little in its own plane).
  double slide_up_to = 15.0 * M_PI / 180;
  double turn_rmse_ratio = 0.7;
  int min_points = 100;
};

struct ArticulationEstimate {
  JointType type = JointType::kPrismatic;
  Eigen::Vector3d axis = Eigen::Vector3d::UnitX();   // unit; the direction the motion went
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();  // a point on the axis (revolute)
  double amount = 0;   // m or rad from the first state to the second (>= 0)
  double fitness = 0;  // share of the moved points matched after the motion
  double rmse = 0;     // m
  core::Pose motion;   // first state -> second state, for the moved part
  // The changed points of each state (their largest cluster: the moving part's surface).
  std::vector<Eigen::Vector3d> moved_before, moved_after;
};

// Throws core::Error when too little changed between the states to tell.
ArticulationEstimate EstimateArticulation(const std::vector<Eigen::Vector3d>& before,
                                          const std::vector<Eigen::Vector3d>& after,
                                          const ArticulationOptions& options = {});

// Furniture joints line up with the furniture: a drawer slides along the normal of one of its
// carcass's faces, a door turns about a vertical or horizontal edge. Turns the estimate's axis
// onto the nearest axis of the upright frame of `frame` (the carcass's points, UprightYaw) when
// it is within `max_angle`, and recomputes the amount (a slide's shift along the new axis) and
// the motion. Returns the angle it turned the axis by (rad), or a negative number if no frame
// axis was near enough.
double SnapToFrame(ArticulationEstimate& estimate, const std::vector<Eigen::Vector3d>& frame,
                   double max_angle = 10.0 * M_PI / 180);

}  // namespace twinforge::real2sim
