#include "real2sim/articulation.h"

#include <open3d/Open3D.h>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <map>

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

// The largest cluster (DBSCAN, `eps`): a moved part is one piece; scattered noise is not.
std::vector<Eigen::Vector3d> LargestCluster(const std::vector<Eigen::Vector3d>& points,
                                            double eps) {
  if (points.empty()) return points;
  open3d::geometry::PointCloud cloud;
  cloud.points_ = points;
  const std::vector<int> labels = cloud.ClusterDBSCAN(eps, 4, /*print_progress=*/false);
  std::map<int, int> counts;
  for (int l : labels)
    if (l >= 0) ++counts[l];
  int best = -1, most = 0;
  for (const auto& [label, n] : counts)
    if (n > most) {
      most = n;
      best = label;
    }
  std::vector<Eigen::Vector3d> out;
  for (std::size_t i = 0; i < points.size(); ++i)
    if (labels[i] == best) out.push_back(points[i]);
  return out;
}

struct Fit {
  Eigen::Vector3d shift = Eigen::Vector3d::Zero();
  double fitness = 0, rmse = 1e300;
};

// ICP restricted to translations (a slide): nearest neighbours within `reach`, then the mean
// offset, until it settles.
Fit FitTranslation(const std::vector<Eigen::Vector3d>& source,
                   const open3d::geometry::KDTreeFlann& tree,
                   const std::vector<Eigen::Vector3d>& target, Eigen::Vector3d shift,
                   double reach) {
  Fit fit;
  std::vector<int> index(1);
  std::vector<double> d2(1);
  for (int iteration = 0; iteration < 60; ++iteration) {
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    double squares = 0;
    int matched = 0;
    for (const auto& p : source) {
      const Eigen::Vector3d q = p + shift;
      if (tree.SearchHybrid(q, reach, 1, index, d2) > 0) {
        sum += target[index[0]] - q;
        squares += d2[0];
        ++matched;
      }
    }
    if (matched == 0) return fit;
    fit.shift = shift;
    fit.fitness = double(matched) / double(source.size());
    fit.rmse = std::sqrt(squares / matched);
    const Eigen::Vector3d step = sum / matched;
    shift += step;
    if (step.norm() < 1e-6) break;
  }
  return fit;
}

}  // namespace

ArticulationEstimate EstimateArticulation(const std::vector<Eigen::Vector3d>& before,
                                          const std::vector<Eigen::Vector3d>& after,
                                          const ArticulationOptions& options,
                                          const PointTest& empty_after,
                                          const PointTest& empty_before) {
  ArticulationEstimate e;
  // Everything below works on a 5 mm grid (a quarter of the ICP reach).
  const double voxel = 0.25 * options.max_correspondence;
  auto thin = [voxel](const std::vector<Eigen::Vector3d>& points) {
    open3d::geometry::PointCloud cloud;
    cloud.points_ = points;
    return cloud.VoxelDownSample(voxel)->points_;
  };
  const std::vector<Eigen::Vector3d> first = thin(before), second = thin(after);
  auto keep = [](std::vector<Eigen::Vector3d> points, const PointTest& test) {
    if (test) std::erase_if(points, [&](const Eigen::Vector3d& p) { return !test(p); });
    return points;
  };
  e.moved_before =
      LargestCluster(keep(Changed(first, second, options.changed), empty_after), 2 * voxel);
  e.moved_after =
      LargestCluster(keep(Changed(second, first, options.changed), empty_before), 2 * voxel);
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
  // The slide that fits best, from where the rigid fit puts the moved points and from the
  // centroids' offset. A flat front fits almost as well turned a little in its own plane, so
  // a slide wins unless turning fits clearly better or turns far.
  const open3d::geometry::KDTreeFlann tree(target);
  Fit slide = FitTranslation(e.moved_before, tree, second, e.motion * from - from,
                             options.max_correspondence);
  const Fit other =
      FitTranslation(e.moved_before, tree, second, to - from, options.max_correspondence);
  if (other.fitness > slide.fitness + 0.02 ||
      (other.fitness > slide.fitness - 0.02 && other.rmse < slide.rmse))
    slide = other;
  const bool turns_far = std::abs(rotation.angle()) > options.slide_up_to;
  const bool turn_fits_better =
      e.fitness > slide.fitness + 0.05 || e.rmse < options.turn_rmse_ratio * slide.rmse;
  if (std::abs(rotation.angle()) < options.prismatic_below || (!turns_far && !turn_fits_better)) {
    e.type = JointType::kPrismatic;
    e.amount = slide.shift.norm();
    e.axis = slide.shift.normalized();
    e.origin = from;
    e.fitness = slide.fitness;
    e.rmse = slide.rmse;
    e.motion = core::Pose{slide.shift, core::Quat::Identity()};
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

double SnapToFrame(ArticulationEstimate& e, const std::vector<Eigen::Vector3d>& frame,
                   double max_angle) {
  const core::Quat yaw = core::Yaw(UprightYaw(frame));
  Eigen::Vector3d best = e.axis;
  double best_angle = max_angle;
  bool found = false;
  for (int i = 0; i < 3; ++i)
    for (double sign : {1.0, -1.0}) {
      const Eigen::Vector3d a = sign * (yaw * Eigen::Vector3d::Unit(i));
      const double angle = std::acos(std::clamp(a.dot(e.axis), -1.0, 1.0));
      if (angle <= best_angle) {
        best_angle = angle;
        best = a;
        found = true;
      }
    }
  if (!found) return -1;
  if (e.type == JointType::kPrismatic) {
    e.amount = e.motion.translation.dot(best);
    e.motion = core::Pose{best * e.amount, core::Quat::Identity()};
  } else {
    const core::Quat r(Eigen::AngleAxisd(e.amount, best));
    e.motion = core::Pose{e.origin - r * e.origin, r};
  }
  e.axis = best;
  return best_angle;
}

void RefitMotion(ArticulationEstimate& e, const std::vector<Eigen::Vector3d>& first,
                 const std::vector<Eigen::Vector3d>& second, const ArticulationOptions& options) {
  if (e.moved_before.empty() || second.empty()) return;
  const Eigen::Vector3d axis = e.axis.normalized();
  if (e.type == JointType::kRevolute) {
    // The panel's width direction: across the axis, along the panel (the moved points spread
    // most that way in the plane normal to the axis).
    const Eigen::Vector3d c = Centroid(e.moved_before);
    Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
    for (const auto& p : e.moved_before) {
      Eigen::Vector3d q = p - c;
      q -= q.dot(axis) * axis;
      cov += q * q.transpose();
    }
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(cov);
    const Eigen::Vector3d width = solver.eigenvectors().col(2);
    const Eigen::Vector3d normal = axis.cross(width);
    double lo = 1e300, hi = -1e300, front = 0;
    for (const auto& p : e.moved_before) {
      lo = std::min(lo, (p - c).dot(width));
      hi = std::max(hi, (p - c).dot(width));
      front += (p - c).dot(normal);
    }
    front /= double(e.moved_before.size());
    // The panel as the first scan saw it: in its plane, at its height, and continuing the moved
    // points without a gap (so the carcass beside it is not taken for it).
    double bottom = 1e300, top = -1e300;
    for (const auto& p : e.moved_before) {
      bottom = std::min(bottom, p.dot(axis));
      top = std::max(top, p.dot(axis));
    }
    std::vector<double> along;
    for (const auto& p : first)
      if (std::abs((p - c).dot(normal) - front) < 0.015 && p.dot(axis) > bottom &&
          p.dot(axis) < top)
        along.push_back((p - c).dot(width));
    std::sort(along.begin(), along.end());
    const auto lo_at = std::lower_bound(along.begin(), along.end(), lo);
    for (auto it = lo_at; it != along.begin() && *(it - 1) > *it - 0.01; --it) lo = *(it - 1);
    const auto hi_at = std::upper_bound(along.begin(), along.end(), hi);
    for (auto it = hi_at; it != along.end() && it != along.begin() && *it < *(it - 1) + 0.01; ++it)
      hi = *it;
    // The end that moved least is the hinge's.
    const Eigen::Vector3d end_lo = c + lo * width, end_hi = c + hi * width;
    const bool hinge_lo = (e.motion * end_lo - end_lo).norm() < (e.motion * end_hi - end_hi).norm();
    Eigen::Vector3d origin = (hinge_lo ? end_lo : end_hi) + front * normal;
    origin += axis * axis.dot(c - origin);
    e.origin = origin;
  }
  // The amount: the best of a 1-D search (robust mean distance of the moved points, each
  // capped at the ICP reach), then refined around it.
  open3d::geometry::PointCloud cloud;
  cloud.points_ = second;
  const open3d::geometry::KDTreeFlann tree(cloud);
  std::vector<int> index(1);
  std::vector<double> d2(1);
  const std::size_t stride = std::max<std::size_t>(1, e.moved_before.size() / 1500);
  auto motion_at = [&](double amount) {
    if (e.type == JointType::kPrismatic) return core::Pose{axis * amount, core::Quat::Identity()};
    const core::Quat r(Eigen::AngleAxisd(amount, axis));
    return core::Pose{e.origin - r * e.origin, r};
  };
  auto cost = [&](double amount) {
    const core::Pose m = motion_at(amount);
    const double cap = options.max_correspondence;
    double sum = 0;
    int n = 0;
    for (std::size_t i = 0; i < e.moved_before.size(); i += stride, ++n) {
      const Eigen::Vector3d q = m * e.moved_before[i];
      sum += tree.SearchKNN(q, 1, index, d2) > 0 ? std::min(std::sqrt(d2[0]), cap) : cap;
    }
    return sum / std::max(1, n);
  };
  const bool slide = e.type == JointType::kPrismatic;
  const double top = slide ? 0.6 : 2.2, step = slide ? 0.004 : 0.01;
  double best = e.amount, best_cost = cost(e.amount);
  for (double a = step; a <= top; a += step)
    if (const double c = cost(a); c < best_cost) {
      best_cost = c;
      best = a;
    }
  for (double a = best - step; a <= best + step; a += step / 10)
    if (const double c = cost(a); a > 0 && c < best_cost) {
      best_cost = c;
      best = a;
    }
  e.amount = best;
  e.motion = motion_at(best);
}

}  // namespace twinforge::real2sim
