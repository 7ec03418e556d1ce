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
  std::vector<Eigen::Vector3d> moved_before, moved_after;  // the changed points of each state
};

// Throws core::Error when too little changed between the states to tell.
ArticulationEstimate EstimateArticulation(const std::vector<Eigen::Vector3d>& before,
                                          const std::vector<Eigen::Vector3d>& after,
                                          const ArticulationOptions& options = {});

}  // namespace twinforge::real2sim
