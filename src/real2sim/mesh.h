// Triangle meshes and planes as real2sim passes them between steps (Open3D stays inside the .cpp
// files). Meshes are written as PLY or OBJ so other tools can open them.
#pragma once

#include <mujoco/mujoco.h>

#include <Eigen/Core>
#include <filesystem>
#include <functional>
#include <memory>
#include <vector>

#include "core/se3.h"

namespace twinforge::real2sim {

struct Mesh {
  std::vector<Eigen::Vector3d> vertices;
  std::vector<Eigen::Vector3d> colors;  // per vertex, 0..1; empty or one per vertex
  std::vector<Eigen::Vector3i> triangles;
  bool empty() const { return triangles.empty(); }
  Eigen::Vector3d min() const;
  Eigen::Vector3d max() const;
  double Area() const;
};

// A plane n.x + d = 0 with |n| = 1.
struct Plane {
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
  double offset = 0;
  double Distance(const Eigen::Vector3d& p) const { return normal.dot(p) + offset; }
  // The z of the plane above (x, y) (a plane that is not vertical).
  double ZAt(const Eigen::Vector2d& xy) const {
    return -(offset + normal.x() * xy.x() + normal.y() * xy.y()) / normal.z();
  }
};

// The triangles for which keep(triangle index) is true, with only the vertices they use.
template <class Keep>
Mesh KeepTriangles(const Mesh& mesh, Keep keep) {
  Mesh out;
  std::vector<int> remap(mesh.vertices.size(), -1);
  for (std::size_t i = 0; i < mesh.triangles.size(); ++i) {
    if (!keep(i)) continue;
    Eigen::Vector3i mapped;
    for (int c = 0; c < 3; ++c) {
      const int v = mesh.triangles[i][c];
      if (remap[v] < 0) {
        remap[v] = static_cast<int>(out.vertices.size());
        out.vertices.push_back(mesh.vertices[v]);
        if (!mesh.colors.empty()) out.colors.push_back(mesh.colors[v]);
      }
      mapped[c] = remap[v];
    }
    out.triangles.push_back(mapped);
  }
  return out;
}

// Adds `from`'s vertices and triangles to `into` (colours kept only if both have them).
void AppendMesh(Mesh& into, const Mesh& from);

// Writes `mesh` as PLY (binary, with colours) or OBJ by the extension. Throws IoError.
void WriteMesh(const std::filesystem::path& path, const Mesh& mesh);
// Reads a PLY or OBJ mesh. Throws IoError naming the file.
Mesh ReadMesh(const std::filesystem::path& path);

// Points on a mesh's surface, area-weighted, deterministic for a seed; with `normals`, also
// the unit normal of the triangle each came from (by the triangle's winding).
std::vector<Eigen::Vector3d> SampleSurface(const Mesh& mesh, int count, uint64_t seed,
                                           std::vector<Eigen::Vector3d>* normals = nullptr);

// For each point of `from`, the distance (m) to the nearest point of `to` (infinity if `to` is
// empty).
std::vector<double> NearestDistances(const std::vector<Eigen::Vector3d>& from,
                                     const std::vector<Eigen::Vector3d>& to);

// The rigid motion that best moves `points` onto `surface`: point-to-plane ICP (Open3D) against
// `samples` points drawn on it, from the identity, correspondences within `reach` m.
core::Pose AlignToSurface(const std::vector<Eigen::Vector3d>& points, const Mesh& surface,
                          double reach, int samples, uint64_t seed);
// The same against several surfaces at once, each with its own number of samples (a wide table
// would otherwise take most of them from a small arm).
struct SampledSurface {
  const Mesh* mesh;
  int samples;
};

// `min_hold` > 0 moves the points only along the directions the pairs hold. At each step the
// pairs resist a small motion along a direction of the twist (about their centroid, a turn
// scaled by their spread, so both are in m) by the sum over pairs of the squared motion along
// each pair's normal, per unit motion: the eigenvalues of the pairs' information matrix. A pair
// moved along its normal by the whole motion adds 1 (for a turn, a pair farther out than the
// spread adds more). A step leaves out the directions held by less than `min_hold` (a plane
// holds its height and tilt, not a slide or a turn in it; an arm seen end-on hardly holds a
// turn about it), so the points keep the motion they came with along those, as of that step
// (Zhang, Kaess and Singh 2016). The directions are found again at every step. The threshold is
// a count of points, so it goes with how densely the points sample the surfaces. 0: Open3D's
// ICP, which slides along them.
core::Pose AlignToSurfaces(const std::vector<Eigen::Vector3d>& points,
                           const std::vector<SampledSurface>& surfaces, double reach, uint64_t seed,
                           double min_hold = 0);

// Whether triangle `t` of `mesh` has (next to) no area: Open3D's distance queries assert on one.
bool Degenerate(const Mesh& mesh, const Eigen::Vector3i& t);

// For each point, its distance (m) to the nearest point of `mesh`'s triangles (Open3D's ray
// casting scene; infinity if the mesh is empty; triangles without area skipped). Exact where
// NearestDistances to samples of a surface is off by their spacing.
std::vector<double> SurfaceDistances(const std::vector<Eigen::Vector3d>& points, const Mesh& mesh);

// A mesh's triangles held for repeated exact queries (Open3D's ray casting scene, kept out of
// this header; triangles without area skipped). `threads`: Open3D's, 0 = all; every point is
// answered alone, so the answers do not depend on it.
class SurfaceQuery {
 public:
  explicit SurfaceQuery(const Mesh& mesh);
  ~SurfaceQuery();
  SurfaceQuery(SurfaceQuery&&) noexcept;
  SurfaceQuery& operator=(SurfaceQuery&&) noexcept;
  // Each point's distance (m) to the triangles (infinity if there are none).
  std::vector<double> Distances(const std::vector<Eigen::Vector3d>& points, int threads = 0) const;
  // Each point's nearest point on the triangles (the mesh must have some); `normals`, if given,
  // gets the unit normal of the triangle each lies on (its winding's side).
  std::vector<Eigen::Vector3d> Closest(const std::vector<Eigen::Vector3d>& points, int threads = 0,
                                       std::vector<Eigen::Vector3d>* normals = nullptr) const;
  // How far each ray, from `origins[i]` along the unit `directions[i]`, goes before it first meets
  // the triangles, from either side (infinity where it never does). Throws core::Error when the
  // counts differ.
  std::vector<double> RayHits(const std::vector<Eigen::Vector3d>& origins,
                              const std::vector<Eigen::Vector3d>& directions) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// The mean of the points (zero for none).
Eigen::Vector3d Centroid(const std::vector<Eigen::Vector3d>& points);

// Mean of the two directed mean nearest-neighbour distances (m): the symmetric Chamfer distance.
double ChamferDistance(const std::vector<Eigen::Vector3d>& a,
                       const std::vector<Eigen::Vector3d>& b);

// The yaw (about +z, in [0, 90) deg) whose frame gives the points the smallest footprint:
// furniture and objects stand upright on the table, so their faces line up with this frame.
double UprightYaw(const std::vector<Eigen::Vector3d>& points);

// The points' bounds in that upright frame (lo, hi in the frame turned by `yaw`).
struct UprightBounds {
  core::Quat yaw = core::Quat::Identity();
  Eigen::Vector3d lo = Eigen::Vector3d::Zero(), hi = Eigen::Vector3d::Zero();
};
UprightBounds UprightBox(const std::vector<Eigen::Vector3d>& points);
// The points' bounds in the frame turned by `yaw` (the identity: axis-aligned bounds).
UprightBounds BoundsIn(const std::vector<Eigen::Vector3d>& points, const core::Quat& yaw);

// The upright box through the median of the surface points near each of its faces: unlike the
// bounds, not widened by depth noise and the fusion's blur (a 2 cm peg's bounds are 2.7 cm).
// Side faces are read from the middle half of the height, away from what is inside (a hole's
// walls); a bottom within `rest` m of `floor` (the support's height) is put on it: a part standing
// on the table, whose bottom no camera sees.
UprightBounds FitUprightBox(const std::vector<Eigen::Vector3d>& points, double floor,
                            double rest = 0.01);

// The upright cylinder that best fits the points of the middle half of the height (the circle
// that most of them lie within `outlier` m of: not a mug's handle), its top and bottom as in
// FitUprightBox. lo/hi are its bounds; yaw is the identity.
UprightBounds FitUprightCylinder(const std::vector<Eigen::Vector3d>& points, double floor,
                                 double rest = 0.01, double outlier = 0.006);

// The rigid motion (point-to-point ICP from the identity, correspondences within `reach` m)
// that best moves `source` onto `target`.
core::Pose AlignPoints(const std::vector<Eigen::Vector3d>& source,
                       const std::vector<Eigen::Vector3d>& target, double reach);

// The geoms of a MuJoCo scene that `keep` accepts, tessellated and posed as `d` has them, in the
// frame whose pose in the world is `frame` (the robot base, usually).
Mesh PosedGeoms(const mjModel* m, const mjData* d, const core::Pose& frame,
                const std::function<bool(int geom)>& keep);

}  // namespace twinforge::real2sim
