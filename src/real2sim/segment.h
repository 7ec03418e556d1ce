// Segmentation of a fused scene: what stands on the support plane, split into clusters, each
// its own mesh (simplified to a budget), labelled as a movable object (small enough to pick up)
// or a fixture (furniture: a candidate for parts, cuts and joints in the twin spec). The rest is
// the static scene (the table and whatever is not above it).
#pragma once

#include <string>
#include <vector>

#include "real2sim/fusion.h"

namespace twinforge::real2sim {

struct SegmentOptions {
  double min_height = 0.008;        // m above the support plane for a point to stand on it
  double cluster_distance = 0.012;  // m: points closer than this are one cluster (DBSCAN eps)
  int min_points = 150;             // smaller clusters are noise
  // m: clusters half of whose points are lower are the table's own edges (TSDF ridges where
  // its border meets its side) or a sheet of its depth noise, not objects
  double min_top = 0.02;
  double movable_extent = 0.2;  // m: clusters at most this wide and tall are movable objects
  int triangle_budget = 3000;   // per segment mesh
  int static_budget = 6000;     // for the static scene's mesh
};

struct Segment {
  std::string name;  // object_0, fixture_1, ... (largest first within each kind)
  bool movable = false;
  Mesh mesh;
  std::vector<Eigen::Vector3d> points;
  Eigen::Vector3d min = Eigen::Vector3d::Zero(), max = Eigen::Vector3d::Zero();
};

struct Segmentation {
  Plane support;
  Mesh static_scene;
  std::vector<Segment> segments;
};

Segmentation SegmentScene(const Fusion& fusion, const SegmentOptions& options);

// Quadric decimation to at most `triangles` triangles (a copy if already within budget).
Mesh Simplify(const Mesh& mesh, int triangles);

}  // namespace twinforge::real2sim
