#include "pipeline/twin_score.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <fstream>
#include <numeric>

#include "core/error.h"
#include "core/scan.h"
#include "real2sim/twin_spec.h"
#include "reality/proxy_reality.h"
#include "sim/camera.h"
#include "sim/geom_scene.h"

namespace twinforge::pipeline {

namespace {

using Points = std::vector<Eigen::Vector3d>;

double Mean(const std::vector<double>& v) {
  return v.empty() ? 0 : std::accumulate(v.begin(), v.end(), 0.0) / double(v.size());
}

double DegreesBetween(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::acos(std::clamp(a.normalized().dot(b.normalized()), -1.0, 1.0)) * 180 / M_PI;
}

// The twin's part `name` and every part jointed below it.
std::vector<std::string> TwinSubtree(const real2sim::TwinSpec& spec, const std::string& name) {
  std::vector<std::string> out{name};
  for (std::size_t i = 0; i < out.size(); ++i)
    for (const auto& j : spec.joints)
      if (j.parent == out[i]) out.push_back(j.child);
  return out;
}

}  // namespace

nlohmann::json TwinScore::ToJson() const {
  nlohmann::json o = nlohmann::json::array(), j = nlohmann::json::array();
  for (const auto& s : objects)
    o.push_back({{"name", s.name},
                 {"found", s.found},
                 {"chamfer_mm", s.chamfer_mm},
                 {"accuracy_mm", s.accuracy_mm},
                 {"completeness_mm", s.completeness_mm},
                 {"position_mm", s.position_mm},
                 {"rotation_deg", s.rotation_deg},
                 {"shift_mm", s.shift_mm},
                 {"tilt_deg", s.tilt_deg},
                 {"solid_position_mm", s.solid_position_mm},
                 {"solid_rotation_deg", s.solid_rotation_deg}});
  for (const auto& s : joints)
    j.push_back({{"name", s.name},
                 {"found", s.found},
                 {"type", s.type},
                 {"twin_type", s.twin_type},
                 {"axis_deg", s.axis_deg},
                 {"axis", s.axis},
                 {"twin_axis", s.twin_axis},
                 {"limit_error", s.limit_error},
                 {"origin_mm", s.origin_mm}});
  nlohmann::json sj = nlohmann::json::array();
  for (const auto& s : sites)
    sj.push_back({{"name", s.name}, {"error_mm", s.error_mm}, {"distance_mm", s.distance_mm}});
  return {{"objects", o},
          {"joints", j},
          {"sites", sj},
          {"mean_chamfer_mm", mean_chamfer_mm},
          {"max_axis_deg", max_axis_deg},
          {"pass", pass}};
}

TwinScore ScoreTwin(const std::filesystem::path& twin_dir, const std::filesystem::path& world_dir,
                    const TwinScoreOptions& options) {
  const real2sim::TwinSpec twin = real2sim::LoadTwinSpec(twin_dir / "twin.yaml");
  std::ifstream build_file(twin_dir / "build.json");
  if (!build_file)
    throw core::IoError("no build.json in " + twin_dir.string() + ": not a `twin build` output");
  const nlohmann::json build = nlohmann::json::parse(build_file);
  const core::Scan scan = core::ReadScan(build.at("scan").get<std::string>());

  reality::ProxyReality world(world_dir);  // as it starts: what the first scan saw
  const sim::Env& env = world.hidden_env();
  const mjModel* m = env.model();
  const mjData* d = env.data();
  const core::Pose base_inv = env.base().Inverse();
  const sim::TaskSpec& task = env.task().spec();
  const sim::Workspace everywhere{Eigen::Vector3f::Constant(-1e6f),
                                  Eigen::Vector3f::Constant(1e6f)};

  // The scan views, scaled down, rendered once: which geom each pixel sees, and where.
  std::vector<std::pair<int, Eigen::Vector3d>> seen;  // geom, base-frame point
  for (const auto& frame : scan.frames) {
    core::PinholeIntrinsics k = frame.intrinsics;
    const double s = double(options.render_width) / k.width;
    k.width = options.render_width;
    k.height = std::max(1, int(std::lround(k.height * s)));
    k.fx *= s, k.fy *= s, k.cx *= s, k.cy *= s;
    sim::RayCaster caster({k, frame.camera_to_base}, m);
    std::vector<float> depth(std::size_t(k.width) * k.height);
    std::vector<int> geom(depth.size());
    caster.Render(m, d, env.base(), depth.data(), nullptr, true, geom.data());
    for (int v = 0; v < k.height; ++v)
      for (int u = 0; u < k.width; ++u) {
        const std::size_t i = std::size_t(v) * k.width + u;
        if (depth[i] <= 0 || geom[i] < 0) continue;
        const Eigen::Vector3d local((u - k.cx) / k.fx * depth[i], (v - k.cy) / k.fy * depth[i],
                                    depth[i]);
        seen.emplace_back(geom[i], frame.camera_to_base * local);
      }
  }

  TwinScore score;
  std::vector<double> chamfers;
  for (const auto& name : task.objects) {
    ObjectScore o;
    o.name = name;
    const int root = mj_name2id(m, mjOBJ_BODY, name.c_str());
    if (root < 0) throw core::Error("world " + world_dir.string() + " has no body " + name);
    auto mine = [&](int g) {
      return sim::InSubtree(m, m->geom_bodyid[g], root) && sim::GeomRgba(m, g)[3] > 0;
    };
    // The world's surface as triangles, for exact distances to it.
    const real2sim::Mesh world_mesh = real2sim::PosedGeoms(m, d, env.base(), mine);
    const sim::SurfaceSampler sampler(m, ~0u, options.density, 16, 200000, mine);
    std::vector<float> xyz(3 * std::size_t(sampler.capacity()));
    const int n = sampler.Transform(m, d, env.base(), everywhere, xyz.data());
    Points full, visible, twin_points;
    real2sim::Mesh twin_mesh, solids;
    for (int i = 0; i < n; ++i) full.emplace_back(xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]);
    for (const auto& [g, p] : seen)
      if (mine(g)) visible.push_back(p);
    for (const auto& part_name : TwinSubtree(twin, name))
      for (const auto& part : twin.parts)
        if (part.name == part_name) {
          real2sim::Mesh mesh = real2sim::PartMesh(part, twin_dir);
          // What is seen: the scan and the boxes added to it, not the solids fitted to it.
          for (const auto& box : part.boxes)
            if (!box.hidden) real2sim::AppendMesh(mesh, real2sim::BoxMesh(box));
          const int count = std::max(100, int(mesh.Area() * options.density));
          const Points p = real2sim::SampleSurface(mesh, count, 7);
          real2sim::AppendMesh(twin_mesh, mesh);
          twin_points.insert(twin_points.end(), p.begin(), p.end());
          if (part.collision == real2sim::PartSpec::Collision::kSolids)
            for (const auto& box : part.boxes) real2sim::AppendMesh(solids, real2sim::BoxMesh(box));
          o.found = true;
        }
    if (o.found && !full.empty() && !visible.empty()) {
      o.accuracy_mm = 1000 * Mean(real2sim::SurfaceDistances(twin_points, world_mesh));
      o.completeness_mm = 1000 * Mean(real2sim::SurfaceDistances(visible, twin_mesh));
      o.chamfer_mm = 0.5 * (o.accuracy_mm + o.completeness_mm);
      // The rigid motion that best moves `points` onto the world's: how far it moves their own
      // centre (its translation alone would count a turn about the robot's base as a shift), by
      // what angle it turns them, and how far it tilts their up axis.
      struct PoseError {
        Eigen::Vector3d shift_mm;
        double position_mm, rotation_deg, tilt_deg;
      };
      auto pose_error = [&](const Points& points) {
        const core::Pose fix = real2sim::AlignPoints(points, full, 0.02);
        const Eigen::Vector3d centre = real2sim::Centroid(points);
        const Eigen::Vector3d shift = 1000 * (fix * centre - centre);
        const Eigen::Vector3d up = fix.rotation * Eigen::Vector3d::UnitZ();
        return PoseError{shift, shift.norm(), Eigen::AngleAxisd(fix.rotation).angle() * 180 / M_PI,
                         std::acos(std::clamp(up.z(), -1.0, 1.0)) * 180 / M_PI};
      };
      const PoseError mesh = pose_error(twin_points);
      o.position_mm = mesh.position_mm;
      o.rotation_deg = mesh.rotation_deg;
      o.tilt_deg = mesh.tilt_deg;
      for (int k = 0; k < 3; ++k) o.shift_mm[k] = mesh.shift_mm[k];
      if (!solids.empty()) {
        const PoseError solid = pose_error(real2sim::SampleSurface(
            solids, std::max(100, int(solids.Area() * options.density)), 9));
        o.solid_position_mm = solid.position_mm;
        o.solid_rotation_deg = solid.rotation_deg;
      }
      chamfers.push_back(o.chamfer_mm);
    }
    score.objects.push_back(o);
  }
  for (const auto& name : task.joints) {
    JointScore j;
    j.name = name;
    const int id = mj_name2id(m, mjOBJ_JOINT, name.c_str());
    if (id < 0) throw core::Error("world " + world_dir.string() + " has no joint " + name);
    const bool hinge = m->jnt_type[id] == mjJNT_HINGE;
    j.type = hinge ? "revolute" : "prismatic";
    const Eigen::Vector3d axis = base_inv.rotation * Eigen::Vector3d(d->xaxis + 3 * id);
    const Eigen::Vector3d anchor = base_inv * Eigen::Vector3d(d->xanchor + 3 * id);
    j.axis = {axis.x(), axis.y(), axis.z()};
    for (const auto& tj : twin.joints) {
      if (tj.name != name) continue;
      j.found = true;
      j.twin_type = real2sim::ToString(tj.type);
      j.twin_axis = tj.axis;
      j.axis_deg = DegreesBetween(axis, Eigen::Vector3d(tj.axis.data()));
      j.limit_error = std::abs(tj.range[1] - m->jnt_range[2 * id + 1]);
      if (hinge) {
        const Eigen::Vector3d r = Eigen::Vector3d(tj.origin.data()) - anchor;
        j.origin_mm = 1000 * (r - r.dot(axis.normalized()) * axis.normalized()).norm();
      }
    }
    score.max_axis_deg = std::max(score.max_axis_deg, j.found ? j.axis_deg : 180.0);
    score.joints.push_back(j);
  }
  for (const auto& ts : twin.sites) {
    const int id = mj_name2id(m, mjOBJ_SITE, ts.name.c_str());
    if (id < 0) continue;
    SiteScore s;
    s.name = ts.name;
    s.found = true;
    const Eigen::Vector3d e = 1000 * (Eigen::Vector3d(ts.position.data()) -
                                      base_inv * Eigen::Vector3d(d->site_xpos + 3 * id));
    s.error_mm = {e.x(), e.y(), e.z()};
    s.distance_mm = e.norm();
    score.sites.push_back(s);
  }
  score.mean_chamfer_mm = Mean(chamfers);
  score.pass = score.mean_chamfer_mm <= options.chamfer_mm &&
               score.max_axis_deg <= options.axis_deg &&
               std::all_of(score.objects.begin(), score.objects.end(),
                           [](const ObjectScore& o) { return o.found; }) &&
               std::all_of(score.joints.begin(), score.joints.end(),
                           [](const JointScore& j) { return j.found && j.type == j.twin_type; });
  return score;
}

}  // namespace twinforge::pipeline
