#include "real2sim/export.h"

#include <cmath>
#include <functional>
#include <sstream>

#include "core/error.h"
#include "core/fs.h"
#include "sim/mjcf.h"

namespace twinforge::real2sim {

namespace {

std::string Vec(const Eigen::Vector3d& v) { return sim::FormatNumbers(v.data(), 3); }

std::string Quat(const core::Quat& q) {
  double wxyz[4];
  core::QuatToMj(q, wxyz);
  return sim::FormatNumbers(wxyz, 4);
}

struct Body {
  const PartSpec* part = nullptr;
  Mesh mesh;                                       // base frame
  core::Pose pose;                                 // body frame -> base
  std::vector<AlignedBox> boxes;                   // body frame
  Eigen::Vector3d half = Eigen::Vector3d::Zero();  // half extents in the body frame
  const JointSpec* joint = nullptr;                // the joint that carries it, if any
  std::vector<int> children;
};

}  // namespace

namespace {

// Greedy merge of the occupied voxels of `points` into boxes, each shrunk to its points. No box
// spans more than one layer of cells along `flat` (the normal of the faces being covered, so
// that faces at different depths, a handle in front of a drawer, stay apart).
std::vector<AlignedBox> MergeVoxels(const std::vector<Eigen::Vector3d>& points, double voxel,
                                    int flat) {
  std::vector<AlignedBox> boxes;
  if (points.empty()) return boxes;
  Eigen::Vector3d lo = points.front(), hi = lo;
  for (const auto& p : points) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  const Eigen::Vector3i n = (((hi - lo) / voxel).array().floor().cast<int>() + 1).matrix();
  auto at = [&](int x, int y, int z) { return (std::size_t(z) * n.y() + y) * n.x() + x; };
  auto cell_of = [&](const Eigen::Vector3d& p) {
    const Eigen::Vector3i c = ((p - lo) / voxel).array().floor().cast<int>().min(n.array() - 1);
    return at(c.x(), c.y(), c.z());
  };
  std::vector<uint8_t> occupied(std::size_t(n.x()) * n.y() * n.z(), 0);
  std::vector<int> owner(occupied.size(), -1);  // the box that took each cell
  for (const auto& p : points) occupied[cell_of(p)] = 1;
  auto free_cell = [&](int x, int y, int z) {
    const std::size_t i = at(x, y, z);
    return occupied[i] && owner[i] < 0;
  };
  for (int z = 0; z < n.z(); ++z)
    for (int y = 0; y < n.y(); ++y)
      for (int x = 0; x < n.x(); ++x) {
        if (!free_cell(x, y, z)) continue;
        int x1 = x + 1;
        while (flat != 0 && x1 < n.x() && free_cell(x1, y, z)) ++x1;
        int y1 = y + 1;
        for (bool grow = flat != 1; grow && y1 < n.y(); grow && ++y1)
          for (int xx = x; xx < x1 && grow; ++xx) grow = free_cell(xx, y1, z);
        int z1 = z + 1;
        for (bool grow = flat != 2; grow && z1 < n.z(); grow && ++z1)
          for (int yy = y; yy < y1 && grow; ++yy)
            for (int xx = x; xx < x1 && grow; ++xx) grow = free_cell(xx, yy, z1);
        for (int zz = z; zz < z1; ++zz)
          for (int yy = y; yy < y1; ++yy)
            for (int xx = x; xx < x1; ++xx) owner[at(xx, yy, zz)] = static_cast<int>(boxes.size());
        boxes.push_back({});
      }
  std::vector<Eigen::Vector3d> box_lo(boxes.size(), Eigen::Vector3d::Constant(1e300)),
      box_hi(boxes.size(), Eigen::Vector3d::Constant(-1e300));
  for (const auto& p : points) {
    const int b = owner[cell_of(p)];
    box_lo[b] = box_lo[b].cwiseMin(p);
    box_hi[b] = box_hi[b].cwiseMax(p);
  }
  for (std::size_t b = 0; b < boxes.size(); ++b)
    boxes[b] = {0.5 * (box_lo[b] + box_hi[b]), 0.5 * (box_hi[b] - box_lo[b])};
  return boxes;
}

}  // namespace

std::vector<AlignedBox> CoverWithBoxes(const std::vector<Eigen::Vector3d>& points,
                                       const std::vector<Eigen::Vector3d>& normals, double voxel,
                                       double thickness) {
  std::vector<AlignedBox> boxes;
  for (int axis = 0; axis < 3; ++axis)
    for (int sign : {1, -1}) {
      std::vector<Eigen::Vector3d> group;
      for (std::size_t i = 0; i < points.size(); ++i) {
        int dominant = 0;
        normals[i].cwiseAbs().maxCoeff(&dominant);
        if (dominant == axis && (normals[i][axis] > 0) == (sign > 0)) group.push_back(points[i]);
      }
      for (AlignedBox box : MergeVoxels(group, voxel, axis)) {
        // The face is the box's outer side; the solid is behind it.
        box.centre[axis] -= sign * 0.5 * thickness;
        box.half[axis] += 0.5 * thickness;
        box.half = box.half.cwiseMax(0.5 * thickness);
        boxes.push_back(box);
      }
    }
  return boxes;
}
namespace {

// Boxes (body frame) covering a part's scanned surface, on the finest grid from
// `options.collision_voxel` up that fits `options.max_boxes`; `voxel` gets the grid used.
std::vector<AlignedBox> CoverScan(const Mesh& mesh, const core::Pose& to_body, double area,
                                  const ExportOptions& options, double& voxel_used) {
  std::vector<AlignedBox> boxes;
  for (double voxel = options.collision_voxel;; voxel *= 1.25) {
    const double spacing = voxel / 3;
    const int count = static_cast<int>(std::clamp(area / (spacing * spacing), 2000.0, 400000.0));
    std::vector<Eigen::Vector3d> normals;
    std::vector<Eigen::Vector3d> points = SampleSurface(mesh, count, 11, &normals);
    for (auto& p : points) p = to_body * p;
    for (auto& n : normals) n = to_body.rotation * n;
    boxes = CoverWithBoxes(points, normals, voxel);
    voxel_used = voxel;
    if (static_cast<int>(boxes.size()) <= options.max_boxes) break;
    if (voxel * 1.25 > options.max_collision_voxel) {
      // A scanned surface has specks no coarser grid gets rid of: keep the largest faces.
      std::sort(boxes.begin(), boxes.end(), [](const AlignedBox& x, const AlignedBox& y) {
        auto face = [](const AlignedBox& box) {
          Eigen::Vector3d h = box.half;
          std::sort(h.data(), h.data() + 3);
          return h[1] * h[2];
        };
        return face(x) > face(y);
      });
      boxes.resize(options.max_boxes);
      break;
    }
  }
  return boxes;
}

}  // namespace

ExportReport ExportMjcf(const TwinSpec& spec, const std::filesystem::path& twin_dir,
                        const ExportOptions& options) {
  ValidateTwinSpec(spec, twin_dir, (twin_dir / "twin.yaml").string());
  ExportReport report;
  std::vector<Body> bodies(spec.parts.size());
  std::map<std::string, int> index;
  for (std::size_t i = 0; i < spec.parts.size(); ++i) index[spec.parts[i].name] = int(i);
  for (const auto& j : spec.joints) bodies[index[j.child]].joint = &j;

  for (std::size_t i = 0; i < spec.parts.size(); ++i) {
    Body& b = bodies[i];
    b.part = &spec.parts[i];
    b.mesh = PartMesh(*b.part, twin_dir);
    if (b.mesh.empty())
      throw core::ConfigError((twin_dir / "twin.yaml").string(),
                              "parts[" + std::to_string(i) + "].cuts",
                              "the cuts leave part '" + b.part->name + "' with no triangles");
    const double area = b.mesh.Area();
    // The body frame: upright, turned to the part's faces, centred on its bounds.
    const auto dense = SampleSurface(b.mesh, 20000, 7);
    const UprightBounds bounds = UprightBox(dense);
    b.pose = {bounds.yaw * (0.5 * (bounds.lo + bounds.hi)), bounds.yaw};
    b.half = 0.5 * (bounds.hi - bounds.lo);
    // Collision boxes on a grid coarse enough for the budget (none when the part collides as
    // fitted solids).
    const core::Pose to_body = b.pose.Inverse();
    if (b.part->collision == PartSpec::Collision::kScan)
      b.boxes = CoverScan(b.mesh, to_body, area, options, report.voxel[b.part->name]);
    report.boxes[b.part->name] = static_cast<int>(b.boxes.size());
    // The visual mesh, in the body frame.
    Mesh local = b.mesh;
    for (auto& v : local.vertices) v = to_body * v;
    WriteMesh(twin_dir / "meshes" / "visual" / (b.part->name + ".obj"), local);
  }
  for (std::size_t i = 0; i < bodies.size(); ++i)
    if (bodies[i].joint && bodies[i].joint->parent != "world")
      bodies[index[bodies[i].joint->parent]].children.push_back(int(i));

  std::ostringstream xml;
  xml << "<!-- Twin '" << spec.name << "', exported by twinforge from twin.yaml: visual meshes of\n"
      << "     the scan, collision boxes fitted to each part's surface (groups 2 and 3). -->\n"
      << "<mujoco model=\"" << spec.name << "\">\n  <asset>\n";
  for (const auto& b : bodies)
    xml << "    <mesh name=\"" << b.part->name << "_visual\" file=\"meshes/visual/" << b.part->name
        << ".obj\"/>\n";
  xml << "  </asset>\n  <default>\n    <default class=\"twin_visual\">\n"
      << "      <geom type=\"mesh\" contype=\"0\" conaffinity=\"0\" group=\"2\" mass=\"0\"/>\n"
      << "    </default>\n    <default class=\"twin_collision\">\n"
      << "      <geom type=\"box\" rgba=\"0.4 0.6 0.9 0\" group=\"3\" mass=\"0\"/>\n"
      << "    </default>\n  </default>\n  <worldbody>\n"
      << "    <light pos=\"0.4 0 1.5\" dir=\"0 0 -1\" directional=\"true\"/>\n";
  // The table: a slab under the support plane.
  const double top = SupportOf(spec).ZAt(Eigen::Vector2d::Zero());
  xml << "    <body name=\"table\" pos=\"" << options.table_centre[0] << " "
      << options.table_centre[1] << " " << top - 0.5 * options.table_thickness << "\">\n"
      << "      <geom name=\"table\" type=\"box\" size=\"" << options.table_half[0] << " "
      << options.table_half[1] << " " << 0.5 * options.table_thickness
      << "\" rgba=\"0.72 0.7 0.66 1\" group=\"2\"/>\n    </body>\n";

  std::function<void(int, const core::Pose&, int)> emit = [&](int i, const core::Pose& parent,
                                                              int depth) {
    const Body& b = bodies[i];
    const PartSpec& p = *b.part;
    const std::string pad(2 * depth, ' ');
    const core::Pose local = parent.Inverse() * b.pose;
    xml << pad << "<body name=\"" << p.name << "\" pos=\"" << Vec(local.translation) << "\" quat=\""
        << Quat(local.rotation) << "\">\n";
    const Eigen::Vector3d e = 2 * b.half;  // solid-box inertia of the part's bounds
    const Eigen::Vector3d inertia =
        p.mass / 12 *
        Eigen::Vector3d(e.y() * e.y() + e.z() * e.z(), e.x() * e.x() + e.z() * e.z(),
                        e.x() * e.x() + e.y() * e.y());
    const Eigen::Vector3d com =
        p.com ? b.pose.Inverse() * Eigen::Vector3d(p.com->data()) : Eigen::Vector3d::Zero();
    xml << pad << "  <inertial pos=\"" << Vec(com) << "\" mass=\"" << p.mass << "\" diaginertia=\""
        << Vec(inertia.cwiseMax(1e-6)) << "\"/>\n";
    if (b.joint) {
      const JointSpec& j = *b.joint;
      const Eigen::Vector3d axis =
          b.pose.rotation.inverse() * Eigen::Vector3d(j.axis.data()).normalized();
      const Eigen::Vector3d origin = b.pose.Inverse() * Eigen::Vector3d(j.origin.data());
      const char* type = j.type == JointType::kPrismatic ? "slide" : "hinge";
      if (j.type != JointType::kFixed)
        xml << pad << "  <joint name=\"" << j.name << "\" type=\"" << type << "\" axis=\""
            << Vec(axis) << "\" pos=\"" << Vec(origin) << "\" range=\"" << j.range[0] << " "
            << j.range[1] << "\" damping=\"" << j.damping << "\" frictionloss=\"" << j.frictionloss
            << "\"/>\n";
    } else if (!p.fixed) {
      xml << pad << "  <freejoint name=\"" << p.name << "_free\"/>\n";
    }
    Eigen::Vector3d colour(0.6, 0.6, 0.6);
    if (p.rgba[3] > 0) {
      colour = Eigen::Vector3d(p.rgba[0], p.rgba[1], p.rgba[2]);
    } else if (!b.mesh.colors.empty()) {
      colour.setZero();
      for (const auto& c : b.mesh.colors) colour += c;
      colour /= double(b.mesh.colors.size());
    }
    xml << pad << "  <geom name=\"" << p.name << "_visual\" class=\"twin_visual\" mesh=\"" << p.name
        << "_visual\" rgba=\"" << Vec(colour) << " 1\"/>\n";
    for (std::size_t k = 0; k < p.boxes.size(); ++k) {
      const BoxSpec& solid = p.boxes[k];
      const core::Pose box = b.pose.Inverse() * solid.pose();
      const Eigen::Vector3d half = 0.5 * Eigen::Vector3d(solid.size.data());
      const bool cylinder = solid.shape == SolidShape::kCylinder;
      xml << pad << "  <geom name=\"" << p.name << "_box" << k
          << "\" class=\"twin_collision\" type=\"" << (cylinder ? "cylinder" : "box") << "\" pos=\""
          << Vec(box.translation) << "\" quat=\"" << Quat(box.rotation) << "\" size=\""
          << (cylinder ? sim::FormatNumbers(Eigen::Vector2d(half.x(), half.z()).data(), 2)
                       : Vec(half))
          << "\"";
      if (!solid.hidden) xml << " rgba=\"" << Vec(colour) << " 1\" group=\"2\"";
      xml << " friction=\"" << p.friction << " 0.005 0.0001\"/>\n";
      if (cylinder) {
        // MuJoCo 2.2 gives a cylinder one contact with a flat face, so it rocks and tips where
        // it is set down; box-box gives several. It stands on a thin box inside its base.
        const double foot = 0.002;
        const Eigen::Vector3d at = box * Eigen::Vector3d(0, 0, foot - half.z());
        xml << pad << "  <geom name=\"" << p.name << "_box" << k
            << "_foot\" class=\"twin_collision\" pos=\"" << Vec(at) << "\" quat=\""
            << Quat(box.rotation) << "\" size=\""
            << Vec(Eigen::Vector3d(half.x() / std::sqrt(2.0), half.x() / std::sqrt(2.0), foot))
            << "\" friction=\"" << p.friction << " 0.005 0.0001\"/>\n";
      }
    }
    for (std::size_t k = 0; k < b.boxes.size(); ++k)
      xml << pad << "  <geom name=\"" << p.name << "_c" << k << "\" class=\"twin_collision\" pos=\""
          << Vec(b.boxes[k].centre) << "\" size=\"" << Vec(b.boxes[k].half) << "\" friction=\""
          << p.friction << " 0.005 0.0001\"/>\n";
    for (const auto& s : spec.sites)
      if (s.part == p.name)
        xml << pad << "  <site name=\"" << s.name << "\" pos=\""
            << Vec(b.pose.Inverse() * Eigen::Vector3d(s.position.data())) << "\" quat=\""
            << Quat(b.pose.rotation.inverse() * core::Yaw(s.yaw))
            << "\" size=\"0.01\" group=\"5\"/>\n";
    for (int c : b.children) emit(c, b.pose, depth + 1);
    xml << pad << "</body>\n";
  };
  for (std::size_t i = 0; i < bodies.size(); ++i)
    if (!bodies[i].joint || bodies[i].joint->parent == "world") emit(int(i), core::Pose{}, 2);
  for (const auto& c : options.cameras) {
    // MuJoCo's cameras look along their -z with y up; OpenCV's along +z with y down.
    const core::Quat q = c.pose.rotation * core::Quat(0, 1, 0, 0);
    xml << "    <camera name=\"" << c.name << "\" pos=\"" << Vec(c.pose.translation) << "\" quat=\""
        << Quat(q) << "\" fovy=\"" << c.fovy_deg << "\"/>\n";
  }
  for (const auto& s : spec.sites)
    if (s.part == "world")
      xml << "    <site name=\"" << s.name << "\" pos=\"" << Vec(Eigen::Vector3d(s.position.data()))
          << "\" quat=\"" << Quat(core::Yaw(s.yaw)) << "\" size=\"0.01\" group=\"5\"/>\n";
  xml << "  </worldbody>\n";
  // A jointed part never collides with its parent or the table: their scanned surfaces touch
  // where a real drawer or door has a few mm of play, and the joint is what holds it. (MuJoCo's
  // own parent-child filter skips a parent welded to the world, as furniture is.)
  if (!spec.joints.empty()) {
    xml << "  <contact>\n";
    for (const auto& j : spec.joints) {
      if (j.parent != "world")
        xml << "    <exclude body1=\"" << j.parent << "\" body2=\"" << j.child << "\"/>\n";
      xml << "    <exclude body1=\"table\" body2=\"" << j.child << "\"/>\n";
    }
    xml << "  </contact>\n";
  }
  xml << "</mujoco>\n";
  report.scene = twin_dir / "scene.xml";
  core::WriteFileAtomic(report.scene, xml.str(), /*keep_backup=*/true);
  return report;
}

}  // namespace twinforge::real2sim
