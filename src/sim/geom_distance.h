#pragma once
// How far a point is from a model's geoms, for an actor sorting the points a camera sees among
// the bodies it believes are there.

#include <mujoco/mujoco.h>

#include <Eigen/Geometry>
#include <vector>

namespace twinforge::sim {

class GeomDistance {
 public:
  // Reads the extent of each mesh geom of `m`; the other geoms' sizes are read at each query
  // (distractors are resized at run time).
  explicit GeomDistance(const mjModel* m);

  // How far `point` is from geom `g` of `m`, turned `rotation` about `position` (all in one
  // frame): 0 inside it. Boxes, spheres, cylinders and capsules exactly. A mesh by the box its
  // vertices span in the geom's frame (MuJoCo keeps them there and collides the mesh as their
  // convex hull, which the box holds): a scanned griddle 3.6 cm high stands 3.6 cm high, where
  // its bounding sphere stood 15 cm over the table. Other shapes (ellipsoids) by their bounding
  // sphere.
  double ToGeom(const mjModel* m, int g, const Eigen::Matrix3d& rotation,
                const Eigen::Vector3d& position, const Eigen::Vector3d& point) const;
  // How far `point` (world) is from the nearest of a body's geoms where `d` has them: 0 inside
  // one.
  double ToBody(const mjModel* m, const mjData* d, int body, const Eigen::Vector3d& point) const;

 private:
  std::vector<Eigen::AlignedBox3d> mesh_boxes_;  // by geom; empty for other shapes
};

}  // namespace twinforge::sim
