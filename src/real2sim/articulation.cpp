#include "real2sim/articulation.h"

#include <open3d/Open3D.h>

#include <Eigen/Geometry>

#include "core/error.h"

namespace twinforge::real2sim {

namespace {

// The points of `from` farther than `distance` from every point of `to`.
std::vector<Eigen::Vector3d> Changed(const std::vector<Eigen::Vector3d>& from,
                                     const std::vector<Eigen::Vector3d>& to, double distance) {
  const std::vector<double> nearest = NearestDistances(from, to);
  std::vector<Eigen::Vector3d> out;
  for (std::size_t i = 0; i < from.size(); ++i)
    if (nearest[i] > distance) out.push_back(from[i]);
  return out;
}

Eigen::Vector3d Centroid(const std::vector<Eigen::Vector3d>& points) {
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (const auto& p : points) c += p;
  return c / double(points.size());
}

}  // namespace

ArticulationEstimate EstimateArticulation(const std::vector<Eigen::Vector3d>& before,
                                          const std::vector<Eigen::Vector3d>& after,
                                          const ArticulationOptions& options) {
  ArticulationEstimate e;
  // Everything below works on a 5 mm grid (a quarter of the ICP reach).
  const double voxel = 0.25 * options.max_correspondence;
  auto thin = [voxel](const std::vector<Eigen::Vector3d>& points) {
    open3d::geometry::PointCloud cloud;
    cloud.points_ = points;
    return cloud.VoxelDownSample(voxel)->points_;
  };
  const std::vector<Eigen::Vector3d> first = thin(before), second = thin(after);
  e.moved_before = Changed(first, second, options.changed);
  e.moved_after = Changed(second, first, options.changed);
  if (static_cast<int>(e.moved_before.size()) < options.min_points ||
      static_cast<int>(e.moved_after.size()) < options.min_points)
    throw core::Error("articulation: only " + std::to_string(e.moved_before.size()) + " / " +
                      std::to_string(e.moved_after.size()) +
                      " points changed between the two scans; did the part move?");
  // The moved points of the first state go onto the whole second state: its changed points
  // alone are a different part of the moving surface (a drawer's tray overlaps itself).
  open3d::geometry::PointCloud source, target;
  source.points_ = e.moved_before;
  target.points_ = second;
  const Eigen::Vector3d from = Centroid(e.moved_before), to = Centroid(e.moved_after);
  // ICP from a fan of starting rotations (about each axis, through the moved points' centre):
  // doors swing by tens of degrees, farther than ICP reaches from one start.
  open3d::pipelines::registration::RegistrationResult best;
  best.fitness_ = -1;
  // A short ICP from every start, then a long one from the best.
  const open3d::pipelines::registration::ICPConvergenceCriteria coarse(1e-6, 1e-6, 12),
      fine(1e-7, 1e-7, 60);
  for (int axis = 0; axis < 3; ++axis)
    for (int deg = -90; deg <= 90; deg += 15) {
      if (deg == 0 && axis > 0) continue;
      const Eigen::Matrix3d r =
          Eigen::AngleAxisd(deg * M_PI / 180, Eigen::Vector3d::Unit(axis)).toRotationMatrix();
      Eigen::Matrix4d init = Eigen::Matrix4d::Identity();
      init.block<3, 3>(0, 0) = r;
      init.block<3, 1>(0, 3) = to - r * from;
      const auto result = open3d::pipelines::registration::RegistrationICP(
          source, target, options.max_correspondence, init,
          open3d::pipelines::registration::TransformationEstimationPointToPoint(false), coarse);
      if (result.fitness_ > best.fitness_ + 1e-9 ||
          (std::abs(result.fitness_ - best.fitness_) <= 1e-9 &&
           result.inlier_rmse_ < best.inlier_rmse_))
        best = result;
    }
  best = open3d::pipelines::registration::RegistrationICP(
      source, target, options.max_correspondence, best.transformation_,
      open3d::pipelines::registration::TransformationEstimationPointToPoint(false), fine);
  e.fitness = best.fitness_;
  e.rmse = best.inlier_rmse_;
  e.motion = core::Pose::FromMatrix(best.transformation_);
  const Eigen::AngleAxisd rotation(e.motion.rotation);
  const Eigen::Vector3d t = e.motion.translation;
  if (std::abs(rotation.angle()) < options.prismatic_below) {
    // A slide: the moved points' displacement, whatever small rotation ICP left in.
    const Eigen::Vector3d shift = e.motion * from - from;
    e.type = JointType::kPrismatic;
    e.amount = shift.norm();
    e.axis = shift.normalized();
    e.origin = from;
    return e;
  }
  e.type = JointType::kRevolute;
  e.axis = rotation.axis();
  e.amount = rotation.angle();
  if (e.amount < 0) {
    e.axis = -e.axis;
    e.amount = -e.amount;
  }
  // A point c on the axis is fixed by the motion: (I - R) c = t, solved in the plane normal to
  // the axis (least squares), then moved along the axis next to the moved points.
  const Eigen::Matrix3d a = Eigen::Matrix3d::Identity() - e.motion.rotation.toRotationMatrix();
  Eigen::Vector3d c = a.completeOrthogonalDecomposition().solve(t);
  c += e.axis * e.axis.dot(from - c);
  e.origin = c;
  return e;
}

}  // namespace twinforge::real2sim
