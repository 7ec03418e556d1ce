#include "real2sim/calibrate/twin_geometry.h"

#include <spdlog/spdlog.h>

#include "core/error.h"
#include "real2sim/segment.h"
#include "sim/geom_scene.h"

namespace twinforge::real2sim {

namespace {
const auto kDouble = torch::TensorOptions().dtype(torch::kFloat64);
}  // namespace

TwinGeometry::TwinGeometry(const sim::TaskSpec& spec, int mesh_triangles)
    : task_(std::make_shared<const sim::Task>(spec)), env_(task_) {
  const mjModel* m = env_.model();
  for (int g = 0; g < m->ngeom; ++g) {
    if (!sim::GeomShown(m, g)) continue;
    const sim::TriangleMesh t = sim::TessellateGeom(m, g);
    if (t.triangles.empty()) continue;
    Mesh mesh;
    for (size_t i = 0; i + 2 < t.vertices.size(); i += 3)
      mesh.vertices.emplace_back(t.vertices[i], t.vertices[i + 1], t.vertices[i + 2]);
    for (size_t i = 0; i + 2 < t.triangles.size(); i += 3)
      mesh.triangles.emplace_back(t.triangles[i], t.triangles[i + 1], t.triangles[i + 2]);
    if (static_cast<int>(mesh.triangles.size()) > mesh_triangles)
      mesh = Simplify(mesh, mesh_triangles);
    Piece piece;
    piece.geom = g;
    piece.mesh = std::move(mesh);
    if (t.unit) {
      const auto s = sim::UnitShapeScale(m, g);
      for (auto& v : piece.mesh.vertices) v = v.cwiseProduct(Eigen::Vector3d(s[0], s[1], s[2]));
    }
    const float* rgba = sim::GeomRgba(m, g);
    piece.color = Eigen::Vector3d(rgba[0], rgba[1], rgba[2]);
    spdlog::debug("calibrate: geom {} renders as {} triangles", g, piece.mesh.triangles.size());
    pieces_.push_back(std::move(piece));
  }
  if (pieces_.empty())
    throw core::ConfigError(spec.file.string(), "scene", "a twin scene with visible geoms");
}

void TwinGeometry::PoseArm(const std::array<double, 7>& q, double gripper_width) {
  mjData* d = env_.mutable_data();
  const auto& robot = task_->index().robot;
  for (int i = 0; i < sim::kArmDof; ++i) d->qpos[robot.arm_qpos[i]] = q[i];
  for (int i = 0; i < 2; ++i) d->qpos[robot.finger_qpos[i]] = 0.5 * gripper_width;
  mj_kinematics(env_.model(), d);
}

void TwinGeometry::RayCast(const std::array<double, 7>& q, double gripper_width,
                           const sim::Camera& camera, std::vector<float>* depth,
                           std::vector<int>* geom) {
  PoseArm(q, gripper_width);
  const int n = camera.intrinsics.width * camera.intrinsics.height;
  depth->resize(n);
  geom->resize(n);
  sim::RayCaster caster(camera, env_.model());
  caster.Render(env_.model(), env_.data(), env_.base(), depth->data(), nullptr, true, geom->data());
}

RasterMesh TwinGeometry::Posed(const std::array<double, 7>& q, double gripper_width,
                               const GeomColor& color, const std::function<bool(int geom)>& keep) {
  const mjData* d = env_.data();
  PoseArm(q, gripper_width);
  const core::Pose to_base = env_.base().Inverse();
  std::vector<double> v, c;
  std::vector<int64_t> f;
  for (const Piece& piece : pieces_) {
    const int g = piece.geom;
    if (keep && !keep(g)) continue;
    const Eigen::Vector3d rgb = color ? color(g) : piece.color;
    const Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> r(d->geom_xmat + 9 * g);
    const Eigen::Map<const Eigen::Vector3d> p(d->geom_xpos + 3 * g);
    const int64_t first = static_cast<int64_t>(v.size() / 3);
    for (const auto& local : piece.mesh.vertices) {
      const Eigen::Vector3d x = to_base * Eigen::Vector3d(r * local + p);
      v.insert(v.end(), {x.x(), x.y(), x.z()});
      c.insert(c.end(), {rgb.x(), rgb.y(), rgb.z()});
    }
    for (const auto& t : piece.mesh.triangles)
      f.insert(f.end(), {first + t[0], first + t[1], first + t[2]});
  }
  RasterMesh mesh;
  const int64_t nv = static_cast<int64_t>(v.size() / 3), nf = static_cast<int64_t>(f.size() / 3);
  mesh.vertices = torch::from_blob(v.data(), {nv, 3}, kDouble).clone();
  mesh.colors = torch::from_blob(c.data(), {nv, 3}, kDouble).clone();
  mesh.faces =
      torch::from_blob(f.data(), {nf, 3}, torch::TensorOptions().dtype(torch::kInt64)).clone();
  return mesh;
}

}  // namespace twinforge::real2sim
