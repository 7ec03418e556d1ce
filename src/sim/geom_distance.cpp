#include "sim/geom_distance.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace twinforge::sim {

GeomDistance::GeomDistance(const mjModel* m) : mesh_boxes_(m->ngeom) {
  for (int g = 0; g < m->ngeom; ++g) {
    if (m->geom_type[g] != mjGEOM_MESH) continue;
    const int id = m->geom_dataid[g];
    const float* v = m->mesh_vert + 3 * m->mesh_vertadr[id];
    for (int k = 0; k < m->mesh_vertnum[id]; ++k)
      mesh_boxes_[g].extend(Eigen::Vector3d(v[3 * k], v[3 * k + 1], v[3 * k + 2]));
  }
}

double GeomDistance::ToGeom(const mjModel* m, int g, const Eigen::Matrix3d& rotation,
                            const Eigen::Vector3d& position, const Eigen::Vector3d& point) const {
  const Eigen::Vector3d q = rotation.transpose() * (point - position);
  const double* size = m->geom_size + 3 * g;
  switch (m->geom_type[g]) {
    case mjGEOM_BOX:
      return (q.cwiseAbs() - Eigen::Map<const Eigen::Vector3d>(size)).cwiseMax(0.0).norm();
    case mjGEOM_SPHERE:
      return std::max(q.norm() - size[0], 0.0);
    case mjGEOM_CYLINDER:
      return std::hypot(std::max(q.head<2>().norm() - size[0], 0.0),
                        std::max(std::abs(q.z()) - size[1], 0.0));
    case mjGEOM_CAPSULE:
      return std::max(
          (q - Eigen::Vector3d(0, 0, std::clamp(q.z(), -size[1], size[1]))).norm() - size[0], 0.0);
    case mjGEOM_MESH:
      if (!mesh_boxes_.at(g).isEmpty()) return mesh_boxes_[g].exteriorDistance(q);
      [[fallthrough]];
    default:
      return std::max(q.norm() - m->geom_rbound[g], 0.0);
  }
}

double GeomDistance::ToBody(const mjModel* m, const mjData* d, int body,
                            const Eigen::Vector3d& point) const {
  double nearest = std::numeric_limits<double>::infinity();
  for (int g = 0; g < m->ngeom; ++g) {
    if (m->geom_bodyid[g] != body) continue;
    const Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> rotation(d->geom_xmat +
                                                                                  9 * g);
    nearest = std::min(
        nearest,
        ToGeom(m, g, rotation, Eigen::Map<const Eigen::Vector3d>(d->geom_xpos + 3 * g), point));
  }
  return nearest;
}

}  // namespace twinforge::sim
