#include "real2sim/segment.h"

#include <open3d/Open3D.h>

#include <algorithm>
#include <map>

#include "core/error.h"

namespace twinforge::real2sim {

Mesh Simplify(const Mesh& mesh, int triangles) {
  if (static_cast<int>(mesh.triangles.size()) <= triangles) return mesh;
  open3d::geometry::TriangleMesh m;
  m.vertices_ = mesh.vertices;
  m.vertex_colors_ = mesh.colors;
  m.triangles_ = mesh.triangles;
  const auto simple =
      m.SimplifyQuadricDecimation(triangles, std::numeric_limits<double>::infinity(), 1.0);
  simple->RemoveUnreferencedVertices();
  return {simple->vertices_, simple->vertex_colors_, simple->triangles_};
}

namespace {

// The part of `mesh` whose triangles have every vertex labelled `label`.
Mesh Submesh(const Mesh& mesh, const std::vector<int>& vertex_label, int label) {
  return KeepTriangles(mesh, [&](std::size_t i) {
    const auto& t = mesh.triangles[i];
    return vertex_label[t[0]] == label && vertex_label[t[1]] == label &&
           vertex_label[t[2]] == label;
  });
}

}  // namespace

Segmentation SegmentScene(const Fusion& fusion, const SegmentOptions& options) {
  Segmentation out;
  out.support = fusion.support;
  // Cluster the points standing on the support plane.
  open3d::geometry::PointCloud above;
  for (const auto& p : fusion.points)
    if (fusion.support.Distance(p) > options.min_height) above.points_.push_back(p);
  std::vector<int> labels;
  if (!above.points_.empty())
    labels = above.ClusterDBSCAN(options.cluster_distance, 8, /*print_progress=*/false);
  std::map<int, std::vector<Eigen::Vector3d>> clusters;
  for (std::size_t i = 0; i < labels.size(); ++i)
    if (labels[i] >= 0) clusters[labels[i]].push_back(above.points_[i]);
  std::vector<std::vector<Eigen::Vector3d>> kept;
  for (auto& [label, points] : clusters) {
    if (static_cast<int>(points.size()) < options.min_points) continue;
    // Half the points must stand higher than min_top: a sheet of table noise a few mm up,
    // chained over half a metre, always has some points higher still, but an object's sides
    // and top put most of its points well up.
    std::vector<double> heights;
    for (const auto& p : points) heights.push_back(fusion.support.Distance(p));
    const auto median = heights.begin() + heights.size() / 2;
    std::nth_element(heights.begin(), median, heights.end());
    if (*median >= options.min_top) kept.push_back(std::move(points));
  }
  // Largest first, ties by position, so names do not depend on DBSCAN's label order.
  std::sort(kept.begin(), kept.end(), [](const auto& a, const auto& b) {
    if (a.size() != b.size()) return a.size() > b.size();
    return a.front().x() < b.front().x();
  });

  // Each mesh vertex belongs to the cluster of its nearest clustered point, if near enough.
  open3d::geometry::PointCloud labelled;
  std::vector<int> point_label;
  for (std::size_t c = 0; c < kept.size(); ++c)
    for (const auto& p : kept[c]) {
      labelled.points_.push_back(p);
      point_label.push_back(static_cast<int>(c));
    }
  std::vector<int> vertex_label(fusion.mesh.vertices.size(), -1);
  if (!labelled.points_.empty()) {
    open3d::geometry::KDTreeFlann tree(labelled);
    std::vector<int> index(1);
    std::vector<double> d2(1);
    const double reach = 1.5 * options.cluster_distance;
    for (std::size_t v = 0; v < fusion.mesh.vertices.size(); ++v) {
      const auto& p = fusion.mesh.vertices[v];
      if (fusion.support.Distance(p) <= 0.5 * options.min_height) continue;
      if (tree.SearchKNN(p, 1, index, d2) == 1 && d2[0] < reach * reach)
        vertex_label[v] = point_label[index[0]];
    }
  }
  int movable = 0, fixtures = 0;
  for (std::size_t c = 0; c < kept.size(); ++c) {
    Segment s;
    s.points = std::move(kept[c]);
    s.min = s.max = s.points.front();
    for (const auto& p : s.points) {
      s.min = s.min.cwiseMin(p);
      s.max = s.max.cwiseMax(p);
    }
    const Eigen::Vector3d extent = s.max - s.min;
    s.movable = extent.maxCoeff() <= options.movable_extent;
    s.name =
        s.movable ? "object_" + std::to_string(movable++) : "fixture_" + std::to_string(fixtures++);
    s.mesh =
        Simplify(Submesh(fusion.mesh, vertex_label, static_cast<int>(c)), options.triangle_budget);
    out.segments.push_back(std::move(s));
  }
  out.static_scene = Simplify(Submesh(fusion.mesh, vertex_label, -1), options.static_budget);
  return out;
}

}  // namespace twinforge::real2sim
