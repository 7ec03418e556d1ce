#include "real2sim/mesh.h"

#include <open3d/Open3D.h>

#include <numeric>

#include "core/error.h"
#include "core/fs.h"
#include "core/rng.h"

namespace twinforge::real2sim {

Eigen::Vector3d Mesh::min() const {
  Eigen::Vector3d m = Eigen::Vector3d::Constant(1e300);
  for (const auto& v : vertices) m = m.cwiseMin(v);
  return m;
}

Eigen::Vector3d Mesh::max() const {
  Eigen::Vector3d m = Eigen::Vector3d::Constant(-1e300);
  for (const auto& v : vertices) m = m.cwiseMax(v);
  return m;
}

double Mesh::Area() const {
  double area = 0;
  for (const auto& t : triangles)
    area += 0.5 * (vertices[t[1]] - vertices[t[0]]).cross(vertices[t[2]] - vertices[t[0]]).norm();
  return area;
}

void WriteMesh(const std::filesystem::path& path, const Mesh& mesh) {
  open3d::geometry::TriangleMesh m;
  m.vertices_ = mesh.vertices;
  m.vertex_colors_ = mesh.colors;
  m.triangles_ = mesh.triangles;
  if (path.has_parent_path()) core::EnsureDirectory(path.parent_path());
  // Written beside and renamed into place, so a reader never sees half a mesh.
  const auto temp = path.parent_path() / (".partial_" + path.filename().string());
  if (!open3d::io::WriteTriangleMesh(temp.string(), m, /*write_ascii=*/path.extension() == ".obj",
                                     /*compressed=*/false, /*write_vertex_normals=*/false,
                                     /*write_vertex_colors=*/!mesh.colors.empty(),
                                     /*write_triangle_uvs=*/false, /*print_progress=*/false))
    throw core::IoError("cannot write mesh " + path.string());
  std::filesystem::rename(temp, path);
}

Mesh ReadMesh(const std::filesystem::path& path) {
  if (!std::filesystem::is_regular_file(path))
    throw core::IoError("cannot read mesh " + path.string() + ": no such file");
  open3d::geometry::TriangleMesh m;
  open3d::io::ReadTriangleMeshOptions options;
  options.enable_post_processing = false;
  if (!open3d::io::ReadTriangleMesh(path.string(), m, options) || m.triangles_.empty())
    throw core::IoError("cannot read mesh " + path.string() +
                        ": not a PLY/OBJ mesh with triangles");
  return {m.vertices_, m.vertex_colors_, m.triangles_};
}

std::vector<Eigen::Vector3d> SampleSurface(const Mesh& mesh, int count, uint64_t seed,
                                           std::vector<Eigen::Vector3d>* normals) {
  std::vector<double> cumulative;
  cumulative.reserve(mesh.triangles.size());
  double total = 0;
  for (const auto& t : mesh.triangles) {
    total += 0.5 * (mesh.vertices[t[1]] - mesh.vertices[t[0]])
                       .cross(mesh.vertices[t[2]] - mesh.vertices[t[0]])
                       .norm();
    cumulative.push_back(total);
  }
  std::vector<Eigen::Vector3d> points;
  if (total <= 0) return points;
  core::Rng rng(seed, 0x5a);
  points.reserve(count);
  if (normals) normals->clear();
  for (int i = 0; i < count; ++i) {
    const double pick = rng.Uniform() * total;
    const auto& t = mesh.triangles[std::lower_bound(cumulative.begin(), cumulative.end(), pick) -
                                   cumulative.begin()];
    double a = rng.Uniform(), b = rng.Uniform();
    if (a + b > 1) {
      a = 1 - a;
      b = 1 - b;
    }
    const Eigen::Vector3d e1 = mesh.vertices[t[1]] - mesh.vertices[t[0]],
                          e2 = mesh.vertices[t[2]] - mesh.vertices[t[0]];
    points.push_back(mesh.vertices[t[0]] + a * e1 + b * e2);
    if (normals) normals->push_back(e1.cross(e2).normalized());
  }
  return points;
}

std::vector<double> NearestDistances(const std::vector<Eigen::Vector3d>& from,
                                     const std::vector<Eigen::Vector3d>& to) {
  std::vector<double> distances(from.size(), std::numeric_limits<double>::infinity());
  if (to.empty()) return distances;
  open3d::geometry::PointCloud cloud;
  cloud.points_ = to;
  open3d::geometry::KDTreeFlann tree(cloud);
  std::vector<int> index(1);
  std::vector<double> d2(1);
  for (std::size_t i = 0; i < from.size(); ++i)
    if (tree.SearchKNN(from[i], 1, index, d2) == 1) distances[i] = std::sqrt(d2[0]);
  return distances;
}

Eigen::Vector3d Centroid(const std::vector<Eigen::Vector3d>& points) {
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (const auto& p : points) c += p;
  return c / double(std::max<std::size_t>(1, points.size()));
}

double ChamferDistance(const std::vector<Eigen::Vector3d>& a,
                       const std::vector<Eigen::Vector3d>& b) {
  if (a.empty() || b.empty()) return std::numeric_limits<double>::infinity();
  auto mean = [](const std::vector<double>& d) {
    return std::accumulate(d.begin(), d.end(), 0.0) / double(d.size());
  };
  return 0.5 * (mean(NearestDistances(a, b)) + mean(NearestDistances(b, a)));
}

double UprightYaw(const std::vector<Eigen::Vector3d>& points) {
  const std::size_t stride = std::max<std::size_t>(1, points.size() / 3000);
  auto area = [&](double yaw) {
    const double c = std::cos(yaw), s = std::sin(yaw);
    Eigen::Vector2d lo = Eigen::Vector2d::Constant(1e300), hi = -lo;
    for (std::size_t i = 0; i < points.size(); i += stride) {
      const Eigen::Vector2d p(c * points[i].x() + s * points[i].y(),
                              -s * points[i].x() + c * points[i].y());
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
    }
    return (hi - lo).prod();
  };
  // Whole degrees, then tenths around the best.
  double best_yaw = 0, best_area = 1e300;
  auto consider = [&](double deg) {
    const double yaw = deg * M_PI / 180, a = area(yaw);
    if (a < best_area - 1e-12) {
      best_area = a;
      best_yaw = yaw;
    }
  };
  for (int deg = 0; deg < 90; ++deg) consider(deg);
  const double coarse = best_yaw * 180 / M_PI;
  for (int tenth = -9; tenth <= 9; ++tenth) consider(coarse + 0.1 * tenth);
  return std::fmod(best_yaw + M_PI / 2, M_PI / 2);  // in [0, 90) deg
}

core::Pose AlignPoints(const std::vector<Eigen::Vector3d>& source,
                       const std::vector<Eigen::Vector3d>& target, double reach) {
  open3d::geometry::PointCloud a, b;
  a.points_ = source;
  b.points_ = target;
  const auto result = open3d::pipelines::registration::RegistrationICP(
      a, b, reach, Eigen::Matrix4d::Identity(),
      open3d::pipelines::registration::TransformationEstimationPointToPoint(false),
      open3d::pipelines::registration::ICPConvergenceCriteria(1e-8, 1e-8, 100));
  return core::Pose::FromMatrix(result.transformation_);
}

void AppendMesh(Mesh& into, const Mesh& from) {
  const bool colours = (into.vertices.empty() || !into.colors.empty()) && !from.colors.empty();
  if (!colours) into.colors.clear();
  const int offset = static_cast<int>(into.vertices.size());
  into.vertices.insert(into.vertices.end(), from.vertices.begin(), from.vertices.end());
  if (colours) into.colors.insert(into.colors.end(), from.colors.begin(), from.colors.end());
  for (const auto& t : from.triangles)
    into.triangles.push_back(t + Eigen::Vector3i::Constant(offset));
}

UprightBounds UprightBox(const std::vector<Eigen::Vector3d>& points) {
  UprightBounds b;
  b.yaw = core::Yaw(UprightYaw(points));
  b.lo = Eigen::Vector3d::Constant(1e300);
  b.hi = -b.lo;
  for (const auto& p : points) {
    const Eigen::Vector3d q = b.yaw.inverse() * p;
    b.lo = b.lo.cwiseMin(q);
    b.hi = b.hi.cwiseMax(q);
  }
  return b;
}

}  // namespace twinforge::real2sim
