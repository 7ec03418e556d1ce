#include "real2sim/drawing.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"
#include "sim/model.h"

namespace twinforge::real2sim {

Mesh Drawing::Surface() const {
  Mesh surface;
  for (std::size_t i = 0; i < solids.size(); ++i) {
    Mesh piece = BoxMesh(solids[i]);
    piece.colors.assign(piece.vertices.size(), colours[i]);
    AppendMesh(surface, piece);
  }
  return surface;
}

double Drawing::Depth() const {
  double lowest = 0;
  for (const auto& v : Surface().vertices) lowest = std::min(lowest, v.z());
  return -lowest;
}

Drawing ReadDrawing(const std::filesystem::path& mjcf, const std::string& body) {
  const sim::ModelPtr model = sim::LoadModel(mjcf);
  const mjModel* m = model.get();
  const int b = mj_name2id(m, mjOBJ_BODY, body.c_str());
  if (b < 1)
    throw core::ConfigError(mjcf.string(), "body",
                            "a body named '" + body + "' to draw the twin's part from");
  Drawing d;
  d.body = body;
  d.mass = m->body_mass[b];
  d.com = Eigen::Vector3d(m->body_ipos + 3 * b);
  for (int g = 0; g < m->ngeom; ++g) {
    if (m->geom_bodyid[g] != b) continue;
    const char* name = mj_id2name(m, mjOBJ_GEOM, g);
    const int type = m->geom_type[g];
    if (type != mjGEOM_BOX && type != mjGEOM_CYLINDER)
      throw core::ConfigError(mjcf.string(), std::string("geom ") + (name ? name : "(unnamed)"),
                              "a box or a cylinder (a drawing is made of solids the twin can "
                              "collide as)");
    const mjtNum* size = m->geom_size + 3 * g;
    BoxSpec solid;
    const Eigen::Vector3d at(m->geom_pos + 3 * g);
    solid.center = {at.x(), at.y(), at.z()};
    const Eigen::Vector3d rpy = core::ToRollPitchYaw(core::QuatFromMj(m->geom_quat + 4 * g));
    solid.euler = {rpy.x(), rpy.y(), rpy.z()};
    if (type == mjGEOM_BOX) {
      solid.size = {2 * size[0], 2 * size[1], 2 * size[2]};
    } else {
      solid.shape = SolidShape::kCylinder;
      solid.size = {2 * size[0], 2 * size[0], 2 * size[1]};
    }
    d.solids.push_back(solid);
    const int material = m->geom_matid[g];
    const float* rgba = material >= 0 ? m->mat_rgba + 4 * material : m->geom_rgba + 4 * g;
    d.colours.emplace_back(rgba[0], rgba[1], rgba[2]);
  }
  if (d.solids.empty())
    throw core::ConfigError(mjcf.string(), "body " + body, "at least one box or cylinder geom");
  for (int s = 0; s < m->nsite; ++s)
    if (m->site_bodyid[s] == b) {
      const char* name = mj_id2name(m, mjOBJ_SITE, s);
      if (name) d.sites.push_back({name, Eigen::Vector3d(m->site_pos + 3 * s)});
    }
  return d;
}

DrawingFit PoseDrawing(const Drawing& drawing, const std::vector<Eigen::Vector3d>& points,
                       const Plane& support) {
  if (points.empty())
    throw core::Error("drawing: the scan has no points of '" + drawing.body + "'");
  const Mesh surface = drawing.Surface();
  const SurfaceQuery query(surface);
  const double depth = drawing.Depth();
  // What of the drawing, resting on the table, stands as high as what the scan saw of it.
  double seen_from = 1e300;
  for (const auto& p : points) seen_from = std::min(seen_from, support.Distance(p));
  std::vector<Eigen::Vector3d> visible;
  for (const auto& s : SampleSurface(surface, 3000, 5))
    if (s.z() + depth >= seen_from - 0.002) visible.push_back(s);
  if (visible.empty()) visible = SampleSurface(surface, 3000, 5);
  const Eigen::Vector3d shown = Centroid(visible), centre = Centroid(points);

  // Upright, resting on the table at (x, y).
  auto rest = [&](double yaw, const Eigen::Vector2d& xy) {
    return core::Pose{Eigen::Vector3d(xy.x(), xy.y(), support.ZAt(xy) + depth), core::Yaw(yaw)};
  };
  auto cut = [](double d) { return std::min(d, 0.02); };
  DrawingFit best;
  double best_cost = 1e300;
  for (int k = 0; k < 36; ++k) {
    const double start = k * M_PI / 18;
    const Eigen::Vector3d offset = core::Yaw(start) * shown;
    core::Pose pose = rest(start, (centre - offset).head<2>());
    for (double reach : {0.03, 0.01, 0.005}) {
      Mesh posed = surface;
      for (auto& v : posed.vertices) v = pose * v;
      const core::Pose motion = AlignToSurface(points, posed, reach, 3000, 7);
      pose = motion.Inverse() * pose;
      const Eigen::Vector3d x = pose.rotation * Eigen::Vector3d::UnitX();
      pose = rest(std::atan2(x.y(), x.x()), pose.translation.head<2>());
    }
    // Both ways: the points to the drawing, and the drawing's visible part to the points.
    std::vector<Eigen::Vector3d> local(points.size());
    const core::Pose inverse = pose.Inverse();
    for (std::size_t i = 0; i < points.size(); ++i) local[i] = inverse * points[i];
    double to_drawing = 0, squared = 0;
    for (double d : query.Distances(local, 1)) {
      to_drawing += cut(d);
      squared += cut(d) * cut(d);
    }
    std::vector<Eigen::Vector3d> shown_posed(visible.size());
    for (std::size_t i = 0; i < visible.size(); ++i) shown_posed[i] = pose * visible[i];
    double to_points = 0;
    int covered = 0;
    for (double d : NearestDistances(shown_posed, points)) {
      to_points += cut(d);
      covered += d < 0.005;
    }
    const double cost = to_drawing / double(points.size()) + to_points / double(visible.size());
    if (cost < best_cost) {
      best_cost = cost;
      best.pose = pose;
      best.rms = std::sqrt(squared / double(points.size()));
      best.coverage = double(covered) / double(visible.size());
    }
  }
  best.candidates = 36;
  return best;
}

}  // namespace twinforge::real2sim
