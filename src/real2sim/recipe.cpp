#include "real2sim/recipe.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <optional>

#include "core/config.h"
#include "core/error.h"
#include "core/log.h"
#include "core/measure.h"
#include "real2sim/drawing.h"
#include "real2sim/export.h"

namespace twinforge::real2sim {

namespace {

// A frame whose x is `x` and whose z is as near +z as x allows.
Eigen::Matrix3d FrameAlong(const Eigen::Vector3d& x) {
  Eigen::Vector3d up = Eigen::Vector3d::UnitZ() - x.dot(Eigen::Vector3d::UnitZ()) * x;
  if (up.norm() < 0.3) up = Eigen::Vector3d::UnitY() - x.dot(Eigen::Vector3d::UnitY()) * x;
  Eigen::Matrix3d r;
  r.col(0) = x;
  r.col(2) = up.normalized();
  r.col(1) = r.col(2).cross(r.col(0));
  return r;
}

// The way the surface of a part joined by `joint` moves as the joint opens, near `at`.
Eigen::Vector3d OpeningDirection(const JointSpec& joint, const Eigen::Vector3d& at) {
  const Eigen::Vector3d axis = Eigen::Vector3d(joint.axis.data()).normalized();
  if (joint.type != JointType::kRevolute) return axis;
  const Eigen::Vector3d v = axis.cross(at - Eigen::Vector3d(joint.origin.data()));
  return v.norm() > 1e-9 ? v.normalized() : Eigen::Vector3d::UnitX();
}

// Horizontal extents (larger first) and height of the points, in their upright frame.
Eigen::Vector3d UprightSize(const std::vector<Eigen::Vector3d>& points) {
  const UprightBounds b = UprightBox(points);
  const Eigen::Vector3d e = b.hi - b.lo;
  return {std::max(e.x(), e.y()), std::min(e.x(), e.y()), e.z()};
}

void RenamePart(TwinSpec& spec, const std::string& from, const std::string& to) {
  if (from == to) return;
  for (auto& p : spec.parts)
    if (p.name == from) p.name = to;
  for (auto& j : spec.joints) {
    if (j.parent == from) j.parent = to;
    if (j.child == from) j.child = to;
  }
  for (auto& s : spec.sites)
    if (s.part == from) s.part = to;
}

PartSpec* FindPart(TwinSpec& spec, const std::string& name) {
  for (auto& p : spec.parts)
    if (p.name == name) return &p;
  return nullptr;
}

const JointSpec* JointOf(const TwinSpec& spec, const std::string& child) {
  for (const auto& j : spec.joints)
    if (j.child == child) return &j;
  return nullptr;
}

// A hidden solid (base frame) spanning lo..hi in the upright frame turned by `yaw`.
BoxSpec SolidIn(const core::Quat& yaw, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi,
                bool cylinder = false) {
  BoxSpec box;
  const Eigen::Vector3d centre = yaw * (0.5 * (lo + hi));
  box.center = {centre.x(), centre.y(), centre.z()};
  box.size = {hi.x() - lo.x(), hi.y() - lo.y(), hi.z() - lo.z()};
  box.euler = {0, 0, core::ToRollPitchYaw(yaw).z()};
  box.shape = cylinder ? SolidShape::kCylinder : SolidShape::kBox;
  box.hidden = true;
  return box;
}

// The solids a part of recipe shape "box" or "cylinder" collides as (base frame): the fitted
// box, less `hole` (x, y, depth) down from the middle of its top, as up to five boxes.
std::vector<BoxSpec> FittedSolids(const UprightBounds& fit, bool cylinder,
                                  const std::array<double, 3>& hole) {
  auto solid = [&](const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) {
    return SolidIn(fit.yaw, lo, hi, cylinder);
  };
  const Eigen::Vector3d lo = fit.lo, hi = fit.hi, mid = 0.5 * (lo + hi);
  if (hole[0] <= 0) return {solid(lo, hi)};
  const Eigen::Vector3d h_lo(mid.x() - 0.5 * hole[0], mid.y() - 0.5 * hole[1],
                             hole[2] > 0 ? hi.z() - hole[2] : lo.z());
  const Eigen::Vector3d h_hi(mid.x() + 0.5 * hole[0], mid.y() + 0.5 * hole[1], hi.z());
  std::vector<BoxSpec> walls;
  auto add = [&](const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
    if ((b - a).minCoeff() > 1e-4) walls.push_back(solid(a, b));
  };
  add(lo, {h_lo.x(), hi.y(), hi.z()});                                // -x wall, full depth
  add({h_hi.x(), lo.y(), lo.z()}, hi);                                // +x wall
  add({h_lo.x(), lo.y(), lo.z()}, {h_hi.x(), h_lo.y(), hi.z()});      // -y between them
  add({h_lo.x(), h_hi.y(), lo.z()}, {h_hi.x(), hi.y(), hi.z()});      // +y
  add({h_lo.x(), h_lo.y(), lo.z()}, {h_hi.x(), h_hi.y(), h_lo.z()});  // floor, if not through
  return walls;
}

}  // namespace

MovingPart FindMovingPart(const Segmentation& first, ArticulationEstimate& e,
                          const Mesh& first_mesh, const Mesh& second, double snap) {
  MovingPart out;
  std::vector<Eigen::Vector3d> first_points;
  for (const auto& s : first.segments)
    first_points.insert(first_points.end(), s.points.begin(), s.points.end());
  // The segment holding most of what moved.
  const Segment* segment = nullptr;
  int best = 0;
  for (const auto& s : first.segments) {
    const auto d = NearestDistances(e.moved_before, s.points);
    const int near =
        static_cast<int>(std::count_if(d.begin(), d.end(), [](double v) { return v < 0.015; }));
    if (near > best) {
      best = near;
      segment = &s;
    }
  }
  if (!segment) throw core::Error("articulation: what moved between the scans lies in no segment");
  out.segment = segment->name;
  if (snap > 0) {
    const double turned = SnapToFrame(e, segment->points, snap);
    if (turned >= 0)
      spdlog::info("twin: the joint axis lined up with {}'s faces (turned {:.2f} deg)",
                   segment->name, turned * 180 / M_PI);
  }
  RefitMotion(e, first_points, second.vertices);
  JointSpec joint;
  joint.type = e.type;
  joint.axis = {e.axis.x(), e.axis.y(), e.axis.z()};
  joint.origin = {e.origin.x(), e.origin.y(), e.origin.z()};
  out.opens = OpeningDirection(joint, Centroid(e.moved_before));
  // The region, in a frame along the opening direction.
  const Eigen::Matrix3d r = FrameAlong(out.opens);
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e300), hi = -lo;
  for (const auto& p : e.moved_before) {
    lo = lo.cwiseMin(r.transpose() * p);
    hi = hi.cwiseMax(r.transpose() * p);
  }
  lo.tail<2>().array() -= 0.004;
  hi.tail<2>().array() += 0.004;
  hi.x() += 0.05;  // a handle the depth sensor half lost may float free of the front
  if (e.type == JointType::kPrismatic) {
    // A tray reaches back into its carcass, short of the carcass's back.
    double back = 1e300;
    for (const auto& p : segment->points) back = std::min(back, (r.transpose() * p).x());
    lo.x() = std::min(lo.x(), back + 0.012);
  } else {
    lo.x() -= 0.025;  // a door panel's thickness behind its front
  }
  const Eigen::Vector3d mid = r * (0.5 * (lo + hi)), size = hi - lo;
  out.region.center = {mid.x(), mid.y(), mid.z()};
  out.region.size = {size.x(), size.y(), size.z()};
  const Eigen::Vector3d rpy = core::ToRollPitchYaw(core::Quat(r));
  out.region.euler = {rpy.x(), rpy.y(), rpy.z()};
  // Its surface as the first scan saw it (its front, straight on) and as the second did (what
  // it showed once moved), moved back to the first state.
  auto inside = [&](const Mesh& mesh, const core::Pose& to_first) {
    Mesh part = KeepTriangles(mesh, [&](std::size_t t) {
      const auto& tri = mesh.triangles[t];
      const Eigen::Vector3d c =
          (mesh.vertices[tri[0]] + mesh.vertices[tri[1]] + mesh.vertices[tri[2]]) / 3.0;
      return out.region.Contains(to_first * c);
    });
    for (auto& v : part.vertices) v = to_first * v;
    return part;
  };
  out.mesh = inside(first_mesh, core::Pose{});
  AppendMesh(out.mesh, inside(second, e.motion.Inverse()));
  if (out.mesh.empty())
    throw core::Error("articulation: the scans have no surface where the part is");
  return out;
}

void AddMovingPart(TwinSpec& spec, const MovingPart& moving, const ArticulationEstimate& e,
                   const std::string& name, const std::string& joint,
                   const std::filesystem::path& twin_dir) {
  PartSpec* parent = FindPart(spec, moving.segment);
  if (!parent)
    throw core::Error("articulation: the spec has no part '" + moving.segment +
                      "' to cut the moving part out of");
  parent->cuts.push_back({CutOp::kSubtract, moving.region});
  const std::string parent_name = parent->name;
  // The carcass's depth along the opening, for the range guess.
  const Mesh carcass = PartMesh(*parent, twin_dir);
  double lo = 1e300, hi = -1e300;
  for (const auto& v : carcass.vertices) {
    lo = std::min(lo, v.dot(moving.opens));
    hi = std::max(hi, v.dot(moving.opens));
  }
  PartSpec part;
  part.name = name;
  part.mesh = "meshes/" + name + ".ply";
  part.mass = 0.5;
  WriteMesh(twin_dir / part.mesh, moving.mesh);
  spec.parts.push_back(part);

  JointSpec j;
  j.name = joint;
  j.type = e.type;
  j.parent = parent_name;
  j.child = name;
  j.axis = {e.axis.x(), e.axis.y(), e.axis.z()};
  j.origin = {e.origin.x(), e.origin.y(), e.origin.z()};
  // Drawers come out about three quarters of their carcass's depth; doors swing about a right
  // angle. Never less than the scans showed.
  const double guess = e.type == JointType::kPrismatic ? 0.75 * (hi - lo) : M_PI / 2;
  j.range = {0, std::max(e.amount, guess)};
  spec.joints.push_back(j);
}

namespace {

enum class OnTop : uint8_t { kNo, kStands, kUnder };

// The mean of triangle `t`'s vertex colours.
Eigen::Vector3d TriangleColour(const Mesh& mesh, std::size_t t) {
  const auto& tri = mesh.triangles[t];
  return (mesh.colors[tri[0]] + mesh.colors[tri[1]] + mesh.colors[tri[2]]) / 3.0;
}

// The median of each channel of the triangles' mean colours where `label` is `which` (-1: none).
Eigen::Vector3d MedianColour(const Mesh& mesh, const std::vector<OnTop>& label, OnTop which) {
  std::vector<double> channel[3];
  for (std::size_t t = 0; t < mesh.triangles.size(); ++t) {
    if (label[t] != which) continue;
    const Eigen::Vector3d c = TriangleColour(mesh, t);
    for (int k = 0; k < 3; ++k) channel[k].push_back(c[k]);
  }
  if (channel[0].empty()) return Eigen::Vector3d::Constant(-1);
  return {core::Median(channel[0]), core::Median(channel[1]), core::Median(channel[2])};
}

// What stands on the top in the carrier's own colour is the carrier's: a griddle's lip at the
// pancake's height, against its edge (the scan fuses the two, and the lip's stretch beside the
// pancake passes the disc with it: 6 mm of iron took the pancake 5.8 mm off). Only where the
// two colours differ clearly (a quarter of the range in one channel at least).
void KeepCarriersColour(const Mesh& mesh, std::vector<OnTop>& label) {
  if (mesh.colors.size() != mesh.vertices.size()) return;
  const Eigen::Vector3d carrier = MedianColour(mesh, label, OnTop::kNo),
                        standing = MedianColour(mesh, label, OnTop::kStands);
  if (carrier.x() < 0 || standing.x() < 0 || (carrier - standing).cwiseAbs().maxCoeff() < 0.25)
    return;
  for (std::size_t t = 0; t < mesh.triangles.size(); ++t) {
    if (label[t] != OnTop::kStands) continue;
    const Eigen::Vector3d c = TriangleColour(mesh, t);
    if ((c - carrier).norm() < (c - standing).norm()) label[t] = OnTop::kNo;
  }
}

// Which triangles of `mesh` stand on its top (a pancake on a griddle): its top is the height
// (`top`, m above `support`) most of its surface lies at; what is 3 mm or more above it and
// where a disc of `radius` fits (an opening of the footprint on a 3 mm grid: a lip or a rim
// narrower than the disc drops out) stands on it. The rest within 3 mm of that footprint is
// under it: what the scan made of what it hides (a rim, a curtain down from an overhang).
std::vector<OnTop> StandingOnTop(const Mesh& mesh, const Plane& support, double radius,
                                 double& top) {
  const std::vector<Eigen::Vector3d> samples = SampleSurface(mesh, 40000, 13);
  std::map<long, int> heights;  // 2 mm bins
  for (const auto& p : samples) ++heights[std::lround(support.Distance(p) / 0.002)];
  top = 0.002 * std::max_element(heights.begin(), heights.end(), [](const auto& a, const auto& b) {
                  return a.second < b.second;
                })->first;
  const double above = top + 0.003, cell = 0.003;
  Eigen::Vector2d lo = Eigen::Vector2d::Constant(1e300), hi = -lo;
  for (const auto& p : samples)
    if (support.Distance(p) > above) {
      lo = lo.cwiseMin(p.head<2>());
      hi = hi.cwiseMax(p.head<2>());
    }
  std::vector<OnTop> label(mesh.triangles.size(), OnTop::kNo);
  if (lo.x() > hi.x()) return label;
  const int reach = static_cast<int>(std::ceil(radius / cell));
  lo -= Eigen::Vector2d::Constant((reach + 2) * cell);
  const int nx = static_cast<int>((hi.x() - lo.x()) / cell) + reach + 3,
            ny = static_cast<int>((hi.y() - lo.y()) / cell) + reach + 3;
  auto index = [&](const Eigen::Vector3d& p) {
    const Eigen::Vector2i c = ((p.head<2>() - lo) / cell).array().floor().cast<int>();
    return c.x() >= 0 && c.y() >= 0 && c.x() < nx && c.y() < ny ? c.y() * nx + c.x() : -1;
  };
  std::vector<uint8_t> seen(std::size_t(nx) * ny, 0);
  for (const auto& p : samples)
    if (support.Distance(p) > above && index(p) >= 0) seen[index(p)] = 1;
  // Morphology with a disc of `r` cells: erode (every cell of the disc set) or dilate (any).
  auto morph = [&](const std::vector<uint8_t>& in, int r, bool erode) {
    std::vector<uint8_t> out(in.size(), 0);
    for (int y = 0; y < ny; ++y)
      for (int x = 0; x < nx; ++x) {
        bool all = true, any = false;
        for (int dy = -r; dy <= r; ++dy)
          for (int dx = -r; dx <= r; ++dx) {
            if (dx * dx + dy * dy > r * r) continue;
            const int xx = x + dx, yy = y + dy;
            const bool on = xx >= 0 && yy >= 0 && xx < nx && yy < ny && in[yy * nx + xx];
            all = all && on;
            any = any || on;
          }
        out[y * nx + x] = erode ? all : any;
      }
    return out;
  };
  // Close the gaps between samples first, then open with the disc.
  const auto closed = morph(morph(seen, 1, false), 1, true);
  const auto opened = morph(morph(closed, reach, true), reach, false);
  const auto footprint = morph(opened, 1, false);
  for (std::size_t t = 0; t < mesh.triangles.size(); ++t) {
    const auto& tri = mesh.triangles[t];
    const Eigen::Vector3d c =
        (mesh.vertices[tri[0]] + mesh.vertices[tri[1]] + mesh.vertices[tri[2]]) / 3.0;
    const int i = index(c);
    if (i >= 0 && opened[i] && support.Distance(c) > above)
      label[t] = OnTop::kStands;
    else if (i >= 0 && footprint[i])
      label[t] = OnTop::kUnder;
  }
  KeepCarriersColour(mesh, label);
  return label;
}

// What of `part`'s scanned surface stands 3 mm or more above its fitted box `fit` (a
// griddle's lip), added to its solids as the boxes that cover it.
void AddWhatStandsOnTop(PartSpec& part, const UprightBounds& fit,
                        const std::filesystem::path& twin_dir) {
  std::vector<Eigen::Vector3d> normals, above, above_normals;
  const std::vector<Eigen::Vector3d> points =
      SampleSurface(PartMesh(part, twin_dir), 20000, 17, &normals);
  for (std::size_t i = 0; i < points.size(); ++i) {
    const Eigen::Vector3d q = fit.yaw.inverse() * points[i];
    if (q.z() < fit.hi.z() + 0.003) continue;
    above.push_back(q);
    above_normals.push_back(fit.yaw.inverse() * normals[i]);
  }
  for (const AlignedBox& b : CoverWithBoxes(above, above_normals, 0.005, 0.006))
    part.boxes.push_back(SolidIn(fit.yaw, b.centre - b.half, b.centre + b.half));
}

// Part `part` (its scanned segment) becomes `drawing`, posed where the segment shows it: the
// drawing's surface as its mesh (meshes/<name>_drawing.ply), its solids as what it collides as,
// its mass (unless `mass` > 0) at its centre of mass; its sites join `sites`.
void PoseDrawnPart(PartSpec& part, const Drawing& drawing, double mass, const Plane& support,
                   const std::filesystem::path& twin_dir, std::vector<SiteSpec>& sites) {
  const DrawingFit fit = PoseDrawing(drawing, PartMesh(part, twin_dir).vertices, support);
  const double yaw = core::ToRollPitchYaw(fit.pose.rotation).z();
  spdlog::info(
      "twin: {} drawn at ({:.3f}, {:.3f}, {:.3f}) m, yaw {:.1f} deg: the scan {:.1f} mm (rms) "
      "from it, {:.0f}% of what it shows seen",
      part.name, fit.pose.translation.x(), fit.pose.translation.y(), fit.pose.translation.z(),
      yaw * 180 / M_PI, 1000 * fit.rms, 100 * fit.coverage);
  Mesh surface = drawing.Surface();
  for (auto& v : surface.vertices) v = fit.pose * v;
  part.mesh = "meshes/" + part.name + "_drawing.ply";
  WriteMesh(twin_dir / part.mesh, surface);
  part.cuts.clear();
  part.boxes.clear();
  for (const BoxSpec& solid : drawing.solids) {
    BoxSpec posed = solid;
    const core::Pose pose = fit.pose * solid.pose();
    posed.center = {pose.translation.x(), pose.translation.y(), pose.translation.z()};
    const Eigen::Vector3d rpy = core::ToRollPitchYaw(pose.rotation);
    posed.euler = {rpy.x(), rpy.y(), rpy.z()};
    posed.hidden = true;  // the drawing's surface is what is seen
    part.boxes.push_back(posed);
  }
  part.collision = PartSpec::Collision::kSolids;
  part.mass = mass > 0 ? mass : drawing.mass;
  const Eigen::Vector3d com = fit.pose * drawing.com;
  part.com = std::array<double, 3>{com.x(), com.y(), com.z()};
  for (const auto& site : drawing.sites) {
    const Eigen::Vector3d at = fit.pose * site.at;
    sites.push_back({site.name, part.name, {at.x(), at.y(), at.z()}, yaw});
  }
}

}  // namespace

void ApplyRecipe(TwinSpec& spec, const sim::TwinRecipe& recipe,
                 const std::filesystem::path& twin_dir, const std::filesystem::path& task_file) {
  const std::string origin = task_file.string();
  // Parts: nearest size first, among the parts no joint moves.
  struct Candidate {
    std::string name;
    Eigen::Vector3d size;
    bool taken = false;
  };
  std::vector<Candidate> candidates;
  for (const auto& p : spec.parts)
    if (!JointOf(spec, p.name))
      candidates.push_back({p.name, UprightSize(PartMesh(p, twin_dir).vertices)});
  // Parts that stand on another in its segment are carved out of it once it is named.
  std::vector<bool> done(recipe.parts.size(), false);
  for (std::size_t r = 0; r < recipe.parts.size(); ++r) done[r] = !recipe.parts[r].on.empty();
  std::map<std::string, UprightBounds> fitted;  // parts that collide as fitted solids
  std::vector<SiteSpec> drawn_sites;            // the sites of drawn parts, posed
  const Plane support = SupportOf(spec);
  std::map<std::string, double> tops;  // parts others stand on: their top, m above the table
  // The recipe's kind, mass and friction and what it collides as; `floor`: the z it stands on
  // (none: the table's, under the middle of its scan).
  auto make = [&](const sim::TwinPartRecipe& want, PartSpec& part, std::optional<double> floor) {
    part.fixed = want.fixed;
    if (want.mass > 0) part.mass = want.mass;
    if (want.friction > 0) part.friction = want.friction;
    if (want.shape == "drawing") {
      PoseDrawnPart(part, ReadDrawing(task_file.parent_path() / want.drawing, want.name), want.mass,
                    support, twin_dir, drawn_sites);
    } else if (want.shape != "scan") {
      std::vector<Eigen::Vector3d> points = PartMesh(part, twin_dir).vertices;
      if (!floor) floor = support.ZAt(Centroid(points).head<2>());
      const auto carrier = tops.find(want.name);
      if (carrier != tops.end())  // the solid up to its top; what stands on it comes after
        points.erase(std::remove_if(points.begin(), points.end(),
                                    [&](const Eigen::Vector3d& p) {
                                      return support.Distance(p) > carrier->second + 0.003;
                                    }),
                     points.end());
      const bool cylinder = want.shape == "cylinder";
      const UprightBounds fit =
          cylinder ? FitUprightCylinder(points, *floor) : FitUprightBox(points, *floor);
      fitted[want.name] = fit;
      part.boxes = FittedSolids(fit, cylinder, want.hole);
      part.collision = PartSpec::Collision::kSolids;
      if (carrier != tops.end()) AddWhatStandsOnTop(part, fit, twin_dir);
      const Eigen::Vector3d size = fit.hi - fit.lo;
      spdlog::info("twin: {} collides as a fitted {} ({:.4f} x {:.4f} x {:.4f} m)", want.name,
                   want.shape, size.x(), size.y(), size.z());
    }
  };
  for (std::size_t round = 0; round < recipe.parts.size(); ++round) {
    double best = 1e300;
    std::size_t best_r = 0;
    Candidate* pick = nullptr;
    for (std::size_t r = 0; r < recipe.parts.size(); ++r) {
      if (done[r]) continue;
      const Eigen::Vector3d want(recipe.parts[r].size.data());
      for (auto& c : candidates) {
        if (c.taken) continue;
        const double cost = (c.size.cwiseMax(1e-4).array() / want.array()).log().abs().sum();
        if (cost < best) {
          best = cost;
          best_r = r;
          pick = &c;
        }
      }
    }
    if (!pick) {
      for (std::size_t r = 0; r < recipe.parts.size(); ++r)
        if (!done[r])
          throw core::ConfigError(origin, "twin.parts[" + std::to_string(r) + "]",
                                  "a segment of the scan for '" + recipe.parts[r].name +
                                      "', but every segment is taken (" +
                                      std::to_string(candidates.size()) + " found)");
      break;
    }
    const auto& want = recipe.parts[best_r];
    const Eigen::Vector3d& has = pick->size;
    if (best > 3 * std::log(1.5))
      spdlog::warn("twin: '{}' ({:.3f} x {:.3f} x {:.3f} m) is the nearest to recipe part '{}'",
                   pick->name, has.x(), has.y(), has.z(), want.name);
    spdlog::info("twin: {} is {} ({:.3f} x {:.3f} x {:.3f} m)", pick->name, want.name, has.x(),
                 has.y(), has.z());
    done[best_r] = true;
    pick->taken = true;
    RenamePart(spec, pick->name, want.name);
  }
  std::map<std::string, double> floors;  // the z a part carved out of another stands on
  for (std::size_t r = 0; r < recipe.parts.size(); ++r) {
    const auto& want = recipe.parts[r];
    if (want.on.empty()) continue;
    const std::string field = "twin.parts[" + std::to_string(r) + "].on";
    const auto carrier = std::find_if(recipe.parts.begin(), recipe.parts.end(),
                                      [&](const auto& p) { return p.name == want.on; });
    if (carrier == recipe.parts.end() || !carrier->on.empty() || carrier->shape == "drawing")
      throw core::ConfigError(origin, field,
                              "another part of the recipe with its own segment, not a drawing, "
                              "got '" +
                                  want.on + "'");
    PartSpec& under = *FindPart(spec, want.on);
    const Mesh whole = PartMesh(under, twin_dir);
    const double width = std::min(want.size[0], want.size[1]);
    double top = 0;
    const std::vector<OnTop> label = StandingOnTop(whole, support, 0.25 * width, top);
    const Mesh carved =
        KeepTriangles(whole, [&](std::size_t t) { return label[t] == OnTop::kStands; });
    if (carved.empty())
      throw core::ConfigError(origin, field,
                              "a part standing on '" + want.on + "', but nothing " +
                                  std::to_string(int(0.25 * width * 1000)) +
                                  " mm wide stands on its top");
    PartSpec part;
    part.name = want.name;
    part.mesh = "meshes/" + want.name + ".ply";
    WriteMesh(twin_dir / part.mesh, carved);
    under.mesh = "meshes/" + want.on + ".ply";
    under.cuts.clear();
    WriteMesh(twin_dir / under.mesh,
              KeepTriangles(whole, [&](std::size_t t) { return label[t] == OnTop::kNo; }));
    const Eigen::Vector3d size = UprightSize(carved.vertices);
    spdlog::info("twin: {} stands on {} ({:.3f} m up): {:.3f} x {:.3f} x {:.3f} m", want.name,
                 want.on, top, size.x(), size.y(), size.z());
    spec.parts.push_back(part);
    floors[want.name] = support.ZAt(Centroid(carved.vertices).head<2>()) + top;
    tops[want.on] = top;
  }
  for (const auto& want : recipe.parts) {
    PartSpec& part = *FindPart(spec, want.name);
    const auto floor = floors.find(want.name);
    make(want, part, floor != floors.end() ? std::optional<double>(floor->second) : std::nullopt);
  }
  // Joints: the one whose parent is the recipe's parent.
  for (std::size_t i = 0; i < recipe.joints.size(); ++i) {
    const auto& want = recipe.joints[i];
    JointSpec* joint = nullptr;
    for (auto& j : spec.joints)
      if (j.parent == want.parent) joint = &j;
    if (!joint)
      throw core::ConfigError(origin, "twin.joints[" + std::to_string(i) + "]",
                              "a part that moves in '" + want.parent +
                                  "' between the two scans (build with --scan-after)");
    const JointType type = want.type == "revolute" ? JointType::kRevolute : JointType::kPrismatic;
    if (joint->type != type)
      spdlog::warn("twin: the scans show a {} joint where the recipe expects {} for '{}'",
                   ToString(joint->type), want.type, want.name);
    joint->name = want.name;
    joint->damping = want.damping;
    joint->frictionloss = want.frictionloss;
    const std::string child = joint->child;
    RenamePart(spec, child, want.part);
    FindPart(spec, want.part)->mass = want.mass;
  }
  // Sites.
  spec.sites.clear();
  for (std::size_t i = 0; i < recipe.sites.size(); ++i) {
    const auto& want = recipe.sites[i];
    const PartSpec* part = FindPart(spec, want.part);
    if (!part)
      throw core::ConfigError(origin, "twin.sites[" + std::to_string(i) + "].part",
                              "one of the twin's parts, got '" + want.part + "'");
    const std::vector<Eigen::Vector3d> points = PartMesh(*part, twin_dir).vertices;
    if (points.empty())
      throw core::Error("twin: part '" + part->name + "' has no surface for site " + want.name);
    Eigen::Vector3d at;
    double yaw = UprightYaw(points);
    if (want.handle) {
      Eigen::Vector3d d;
      if (const JointSpec* joint = JointOf(spec, part->name)) {
        d = OpeningDirection(*joint, Centroid(points));
      } else {
        // A free part's handle: the farthest point horizontally from its core (median x, y).
        std::vector<double> xs, ys;
        for (const auto& p : points) {
          xs.push_back(p.x());
          ys.push_back(p.y());
        }
        std::nth_element(xs.begin(), xs.begin() + xs.size() / 2, xs.end());
        std::nth_element(ys.begin(), ys.begin() + ys.size() / 2, ys.end());
        const Eigen::Vector2d core(xs[xs.size() / 2], ys[ys.size() / 2]);
        double far = -1;
        d = Eigen::Vector3d::UnitX();
        for (const auto& p : points)
          if ((p.head<2>() - core).norm() > far) {
            far = (p.head<2>() - core).norm();
            d = Eigen::Vector3d(p.x() - core.x(), p.y() - core.y(), 0).normalized();
          }
      }
      double extreme = -1e300;
      for (const auto& p : points) extreme = std::max(extreme, p.dot(d));
      std::vector<Eigen::Vector3d> band;
      for (const auto& p : points)
        if (p.dot(d) > extreme - 0.01) band.push_back(p);
      at = Centroid(band) - want.inset * d;
      yaw = std::atan2(d.y(), d.x());
    } else {
      // A point of the part's bounds: axis-aligned, or a fitted solid's in the solid's frame.
      const auto fit = fitted.find(part->name);
      const bool solid = fit != fitted.end();
      const UprightBounds b = solid ? fit->second : BoundsIn(points, core::Quat::Identity());
      at = b.yaw * (0.5 * (b.lo + b.hi) +
                    0.5 * (b.hi - b.lo).cwiseProduct(Eigen::Vector3d(want.box.data())));
      if (solid) yaw = core::ToRollPitchYaw(b.yaw).z();
    }
    at += Eigen::Vector3d(want.offset.data());
    spec.sites.push_back(
        {want.name, part->name, {at.x(), at.y(), at.z()}, yaw + want.turn_deg * M_PI / 180});
    // A box at the site: `size` and the centre's `offset` in the site's frame.
    auto site_box = [&](const std::array<double, 3>& size, const std::array<double, 3>& offset) {
      const double site_yaw = spec.sites.back().yaw;
      const Eigen::Vector3d centre = at + core::Yaw(site_yaw) * Eigen::Vector3d(offset.data());
      BoxSpec box;
      box.center = {centre.x(), centre.y(), centre.z()};
      box.size = size;
      box.euler = {0, 0, site_yaw};
      return box;
    };
    if (want.clear_box[0] > 0 && want.clear_box[1] > 0 && want.clear_box[2] > 0) {
      CutSpec cut;
      cut.box = site_box(want.clear_box, want.clear_offset);
      FindPart(spec, want.part)->cuts.push_back(cut);
    }
    if (want.grip_box[0] > 0 && want.grip_box[1] > 0 && want.grip_box[2] > 0)
      FindPart(spec, want.part)->boxes.push_back(site_box(want.grip_box, want.grip_offset));
  }
  spec.sites.insert(spec.sites.end(), drawn_sites.begin(), drawn_sites.end());
}

std::filesystem::path WriteTwinTask(const sim::TaskSpec& task,
                                    const std::filesystem::path& twin_dir) {
  sim::TaskSpec twin = task;
  twin.scene = "scene.xml";
  if (!twin.robot.empty() && std::filesystem::path(twin.robot).is_relative())
    twin.robot = (task.file.parent_path() / twin.robot).lexically_normal().string();
  for (auto& part : twin.twin.parts)
    if (!part.drawing.empty() && std::filesystem::path(part.drawing).is_relative())
      part.drawing = (task.file.parent_path() / part.drawing).lexically_normal().string();
  const auto path = twin_dir / "task.yaml";
  core::SaveConfig(path, twin);
  return path;
}

}  // namespace twinforge::real2sim
