// Articulation from observation: given the scene's surface in two states (e.g. the drawer
// closed, then open after a pull), find what moved and how: joint type, axis, a point on the
// axis (revolute), and how far it moved between the two states.
#pragma once

#include <functional>
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
// With `empty_after` (a point of the first state lies where the second scan saw through: the
// part left it) and `empty_before` (the same the other way: the part moved into it), a changed
// point must also pass them, so that what the motion uncovered (a cabinet's inside behind its
// door) is not taken for the part.
using PointTest = std::function<bool(const Eigen::Vector3d&)>;
ArticulationEstimate EstimateArticulation(const std::vector<Eigen::Vector3d>& before,
                                          const std::vector<Eigen::Vector3d>& after,
                                          const ArticulationOptions& options = {},
                                          const PointTest& empty_after = nullptr,
                                          const PointTest& empty_before = nullptr);

// Furniture joints line up with the furniture: a drawer slides along the normal of one of its
// carcass's faces, a door turns about a vertical or horizontal edge. Turns the estimate's axis
// onto the nearest axis of the upright frame of `frame` (the carcass's points, UprightYaw) when
// it is within `max_angle`, and recomputes the amount (a slide's shift along the new axis) and
// the motion. Returns the angle it turned the axis by (rad), or a negative number if no frame
// axis was near enough.
double SnapToFrame(ArticulationEstimate& estimate, const std::vector<Eigen::Vector3d>& frame,
                   double max_angle = 10.0 * M_PI / 180);

// With the axis direction settled (SnapToFrame), re-fits what ICP pins down worst on a flat
// panel: a hinge goes to the edge of the panel (in the first state's surface `first`, which
// reaches the hinge where the moved points stop short of it) on the side that moved least (a
// small swing leaves the hinge's place poorly determined by ICP: a 1 cm slip at 0.2 rad is 5 cm
// of hinge); and the amount becomes the one along the joint that best lays the moved points onto
// `second` (a 1-D search). Recomputes the motion.
void RefitMotion(ArticulationEstimate& estimate, const std::vector<Eigen::Vector3d>& first,
                 const std::vector<Eigen::Vector3d>& second,
                 const ArticulationOptions& options = {});

}  // namespace twinforge::real2sim
