#include "real2sim/fusion.h"

#include <open3d/Open3D.h>

#include <Eigen/Eigenvalues>

#include "core/error.h"
#include "core/image.h"
#include "core/rng.h"
#include "sim/robot_mask.h"

namespace twinforge::real2sim {

namespace {

bool Inside(const Eigen::Vector3d& p, const FusionOptions& o) {
  return (p.array() >= o.crop_min.array()).all() && (p.array() <= o.crop_max.array()).all();
}

}  // namespace

Plane FitSupportPlane(const std::vector<Eigen::Vector3d>& points, double tolerance, double max_tilt,
                      uint64_t seed, int iterations) {
  if (points.size() < 3) throw core::Error("support plane: fewer than 3 points");
  core::Rng rng(seed, 0x91a);
  Plane best;
  long best_count = -1;
  const double min_up = std::cos(max_tilt);
  // Inliers are counted on a fixed subsample: the fit is refined on all of them below.
  const std::size_t stride = std::max<std::size_t>(1, points.size() / 20000);
  for (int it = 0; it < iterations; ++it) {
    const auto& a = points[rng.Index(points.size())];
    const auto& b = points[rng.Index(points.size())];
    const auto& c = points[rng.Index(points.size())];
    Eigen::Vector3d n = (b - a).cross(c - a);
    if (n.norm() < 1e-9) continue;
    n.normalize();
    if (n.z() < 0) n = -n;
    if (n.z() < min_up) continue;
    const Plane candidate{n, -n.dot(a)};
    long count = 0;
    for (std::size_t i = 0; i < points.size(); i += stride)
      count += std::abs(candidate.Distance(points[i])) < tolerance;
    if (count > best_count) {
      best_count = count;
      best = candidate;
    }
  }
  if (best_count <= 0) throw core::Error("support plane: no near-horizontal plane in the scan");
  // Least squares on the inliers: the normal is the direction of least spread.
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  long n = 0;
  for (const auto& p : points)
    if (std::abs(best.Distance(p)) < tolerance) {
      mean += p;
      ++n;
    }
  mean /= double(n);
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (const auto& p : points)
    if (std::abs(best.Distance(p)) < tolerance) cov += (p - mean) * (p - mean).transpose();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(cov);
  Eigen::Vector3d normal = solver.eigenvectors().col(0);
  if (normal.z() < 0) normal = -normal;
  return {normal, -normal.dot(mean)};
}

std::vector<float> ReadDepthMetres(const core::Scan& scan, const core::ScanFrameInfo& f) {
  const auto& k = f.intrinsics;
  const core::Image png = core::ReadPng(scan.dir / f.depth);
  if (png.width != k.width || png.height != k.height || png.bit_depth != 16)
    throw core::IoError(scan.dir.string() + ": " + f.depth + " is not a 16-bit depth image of " +
                        "the frame's " + std::to_string(k.width) + "x" + std::to_string(k.height));
  const std::size_t n = std::size_t(k.width) * k.height;
  const auto* mm = reinterpret_cast<const uint16_t*>(png.bytes.data());
  std::vector<float> depth(n);
  for (std::size_t i = 0; i < n; ++i) depth[i] = float(mm[i] / scan.depth_scale);
  return depth;
}

FreeSpace::FreeSpace(const core::Scan& scan, double margin, int min_frames)
    : margin_(margin), min_frames_(min_frames) {
  for (const auto& f : scan.frames)
    views_.push_back({f.intrinsics, f.camera_to_base.Inverse(), ReadDepthMetres(scan, f)});
}

bool FreeSpace::SeenThrough(const Eigen::Vector3d& p) const {
  int seen = 0;
  for (const auto& v : views_) {
    const Eigen::Vector3d c = v.base_to_camera * p;
    if (c.z() <= 0.05) continue;
    const int u = int(std::lround(v.k.fx * c.x() / c.z() + v.k.cx)),
              w = int(std::lround(v.k.fy * c.y() / c.z() + v.k.cy));
    if (u < 0 || w < 0 || u >= v.k.width || w >= v.k.height) continue;
    const float d = v.depth[std::size_t(w) * v.k.width + u];
    if (d > 0 && d > c.z() + margin_ && ++seen >= min_frames_) return true;
  }
  return false;
}

Fusion FuseScan(const core::Scan& scan, const sim::RobotSpec& robot, const FusionOptions& options,
                core::Progress* progress) {
  if (scan.frames.empty()) throw core::Error("scan " + scan.dir.string() + " has no frames");
  open3d::pipelines::integration::ScalableTSDFVolume volume(
      options.voxel, options.truncation, open3d::pipelines::integration::TSDFVolumeColorType::RGB8);
  std::unique_ptr<sim::RobotMask> mask;
  if (options.remove_robot) mask = std::make_unique<sim::RobotMask>(robot);
  Fusion fusion;
  std::vector<float> depth;
  for (const auto& f : scan.frames) {
    const auto& k = f.intrinsics;
    const core::Image color = core::ReadPng(scan.dir / f.color);
    if (color.width != k.width || color.height != k.height || color.channels < 3)
      throw core::IoError(scan.dir.string() + ": " + f.color + " is not an RGB image of the " +
                          "frame's " + std::to_string(k.width) + "x" + std::to_string(k.height));
    const std::size_t n = std::size_t(k.width) * k.height;
    depth = ReadDepthMetres(scan, f);
    const sim::Camera camera{k, f.camera_to_base};
    if (mask) {
      mask->Pose(sim::ArmVector(f.joint_positions.data()), f.gripper_width);
      fusion.robot_pixels += mask->Remove(camera, depth, options.robot_margin);
    }
    open3d::geometry::Image o3d_depth, o3d_color;
    o3d_depth.Prepare(k.width, k.height, 1, 4);
    std::memcpy(o3d_depth.data_.data(), depth.data(), 4 * n);
    o3d_color.Prepare(k.width, k.height, 3, 1);
    for (std::size_t i = 0; i < n; ++i)
      for (int c = 0; c < 3; ++c) o3d_color.data_[3 * i + c] = color.bytes[color.channels * i + c];
    const auto rgbd = open3d::geometry::RGBDImage::CreateFromColorAndDepth(
        o3d_color, o3d_depth, 1.0, options.depth_max, false);
    const open3d::camera::PinholeCameraIntrinsic intrinsic(k.width, k.height, k.fx, k.fy, k.cx,
                                                           k.cy);
    volume.Integrate(*rgbd, intrinsic, f.camera_to_base.Matrix().inverse());
    if (progress) progress->Advance();
  }
  const auto mesh = volume.ExtractTriangleMesh();
  // Keep the triangles whose vertices are all inside the crop box.
  const Mesh full{mesh->vertices_, mesh->vertex_colors_, mesh->triangles_};
  fusion.mesh = KeepTriangles(full, [&](std::size_t i) {
    const auto& t = full.triangles[i];
    return Inside(full.vertices[t[0]], options) && Inside(full.vertices[t[1]], options) &&
           Inside(full.vertices[t[2]], options);
  });
  const auto cloud = volume.ExtractPointCloud();
  for (std::size_t i = 0; i < cloud->points_.size(); ++i) {
    if (!Inside(cloud->points_[i], options)) continue;
    fusion.points.push_back(cloud->points_[i]);
    fusion.colors.push_back(cloud->HasColors() ? cloud->colors_[i]
                                               : Eigen::Vector3d(0.5, 0.5, 0.5));
  }
  if (fusion.points.size() < 100)
    throw core::Error("fusing " + scan.dir.string() + " left " +
                      std::to_string(fusion.points.size()) +
                      " surface points: are the depth units and camera poses right?");
  fusion.support = FitSupportPlane(fusion.points, 1.5 * options.voxel, 0.35, options.seed);
  return fusion;
}

}  // namespace twinforge::real2sim
