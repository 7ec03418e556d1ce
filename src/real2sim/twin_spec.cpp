#include "real2sim/twin_spec.h"

#include <algorithm>
#include <cctype>
#include <map>
#include <set>

#include "core/error.h"
#include "core/fs.h"

namespace twinforge::real2sim {

core::Pose BoxSpec::pose() const {
  return {Eigen::Vector3d(center.data()), core::FromRollPitchYaw(euler[0], euler[1], euler[2])};
}

bool BoxSpec::Contains(const Eigen::Vector3d& p) const {
  const Eigen::Vector3d local = pose().Inverse() * p;
  if (shape == SolidShape::kCylinder)
    return std::abs(local.z()) <= 0.5 * size[2] && local.head<2>().norm() <= 0.5 * size[0];
  for (int i = 0; i < 3; ++i)
    if (std::abs(local[i]) > 0.5 * size[i]) return false;
  return true;
}

Plane SupportOf(const TwinSpec& spec) {
  Plane plane;
  plane.normal = Eigen::Vector3d(spec.support[0], spec.support[1], spec.support[2]);
  plane.offset = spec.support[3];
  return plane;
}

const char* ToString(JointType type) {
  switch (type) {
    case JointType::kFixed:
      return "fixed";
    case JointType::kPrismatic:
      return "prismatic";
    case JointType::kRevolute:
      return "revolute";
  }
  return "?";
}

std::vector<std::string> PartsOfMesh(const TwinSpec& spec, const std::string& mesh) {
  std::vector<std::string> names;
  for (const auto& part : spec.parts)
    if (part.mesh == mesh) names.push_back(part.name);
  return names;
}

int MoveParts(TwinSpec& spec, const std::vector<std::string>& parts, const core::Pose& motion) {
  auto move_point = [&](std::array<double, 3>& p) {
    const Eigen::Vector3d moved = motion * Eigen::Vector3d(p.data());
    p = {moved.x(), moved.y(), moved.z()};
  };
  auto move_box = [&](BoxSpec& box) {
    const core::Pose pose = motion * box.pose();
    box.center = {pose.translation.x(), pose.translation.y(), pose.translation.z()};
    const Eigen::Vector3d euler = core::ToRollPitchYaw(pose.rotation);
    box.euler = {euler.x(), euler.y(), euler.z()};
  };
  auto is_moved = [&](const std::string& name) {
    return std::find(parts.begin(), parts.end(), name) != parts.end();
  };
  int moved = 0;
  for (auto& part : spec.parts) {
    if (!is_moved(part.name)) continue;
    for (auto& cut : part.cuts) move_box(cut.box);
    for (auto& box : part.boxes) move_box(box);
    if (part.com) move_point(*part.com);
    ++moved;
  }
  for (auto& site : spec.sites) {
    if (!is_moved(site.part)) continue;
    move_point(site.position);
    // The site's x stays level: its yaw follows where the motion turns it.
    const Eigen::Vector3d x =
        motion.rotation * Eigen::Vector3d(std::cos(site.yaw), std::sin(site.yaw), 0);
    site.yaw = std::atan2(x.y(), x.x());
  }
  for (auto& joint : spec.joints) {
    if (!is_moved(joint.child)) continue;
    move_point(joint.origin);
    const Eigen::Vector3d axis = motion.rotation * Eigen::Vector3d(joint.axis.data());
    joint.axis = {axis.x(), axis.y(), axis.z()};
  }
  return moved;
}

Mesh BoxMesh(const BoxSpec& box) {
  Mesh mesh;
  const core::Pose pose = box.pose();
  const Eigen::Vector3d half = 0.5 * Eigen::Vector3d(box.size.data());
  if (box.shape == SolidShape::kCylinder) {
    // A prism of `sides` faces: ring vertices 2k (bottom) and 2k+1 (top), then the two centres.
    const int sides = 32;
    for (int k = 0; k < sides; ++k) {
      const double a = 2 * M_PI * k / sides;
      for (double z : {-half.z(), half.z()})
        mesh.vertices.push_back(pose *
                                Eigen::Vector3d(half.x() * std::cos(a), half.x() * std::sin(a), z));
    }
    const int bottom = 2 * sides, top = bottom + 1;
    mesh.vertices.push_back(pose * Eigen::Vector3d(0, 0, -half.z()));
    mesh.vertices.push_back(pose * Eigen::Vector3d(0, 0, half.z()));
    for (int k = 0; k < sides; ++k) {
      const int b0 = 2 * k, t0 = b0 + 1, b1 = 2 * ((k + 1) % sides), t1 = b1 + 1;
      mesh.triangles.emplace_back(b0, b1, t1);
      mesh.triangles.emplace_back(b0, t1, t0);
      mesh.triangles.emplace_back(bottom, b1, b0);
      mesh.triangles.emplace_back(top, t0, t1);
    }
    return mesh;
  }
  for (int i = 0; i < 8; ++i)
    mesh.vertices.push_back(pose * Eigen::Vector3d((i & 1 ? 1 : -1) * half.x(),
                                                   (i & 2 ? 1 : -1) * half.y(),
                                                   (i & 4 ? 1 : -1) * half.z()));
  // Two triangles per face, wound outward.
  const int faces[6][4] = {{0, 2, 6, 4}, {1, 5, 7, 3}, {0, 4, 5, 1},
                           {2, 3, 7, 6}, {0, 1, 3, 2}, {4, 6, 7, 5}};
  for (const auto& f : faces) {
    mesh.triangles.emplace_back(f[0], f[1], f[2]);
    mesh.triangles.emplace_back(f[0], f[2], f[3]);
  }
  return mesh;
}

Mesh CutMesh(const Mesh& mesh, const CutSpec& cut) {
  const bool keep_inside = cut.op == CutOp::kIntersect;
  return KeepTriangles(mesh, [&](std::size_t i) {
    const auto& t = mesh.triangles[i];
    const Eigen::Vector3d centroid =
        (mesh.vertices[t[0]] + mesh.vertices[t[1]] + mesh.vertices[t[2]]) / 3.0;
    return cut.box.Contains(centroid) == keep_inside;
  });
}

Mesh PartMesh(const PartSpec& part, const std::filesystem::path& twin_dir) {
  Mesh mesh = ReadMesh(twin_dir / part.mesh);
  for (const auto& cut : part.cuts) mesh = CutMesh(mesh, cut);
  return mesh;
}

void ValidateTwinSpec(const TwinSpec& spec, const std::filesystem::path& twin_dir,
                      const std::string& origin) {
  auto fail = [&](const std::string& field, const std::string& message) {
    throw core::ConfigError(origin, field, message);
  };
  // Names become MJCF names and file names (meshes/visual/<part>.obj).
  auto check_name = [&](const std::string& name, const std::string& field) {
    const bool plain = !name.empty() && std::all_of(name.begin(), name.end(), [](char c) {
      return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '.';
    });
    if (!plain || name == "." || name == "..")
      fail(field, "a name of letters, digits, '_', '-' and '.', got '" + name + "'");
  };
  std::set<std::string> parts;
  for (std::size_t i = 0; i < spec.parts.size(); ++i) {
    const auto& p = spec.parts[i];
    const std::string at = "parts[" + std::to_string(i) + "]";
    check_name(p.name, at + ".name");
    if (p.name == "world") fail(at + ".name", "'world' is reserved for the static scene");
    if (!parts.insert(p.name).second) fail(at + ".name", "a second part named '" + p.name + "'");
    const std::filesystem::path mesh(p.mesh);
    if (mesh.is_absolute() || std::find(mesh.begin(), mesh.end(), "..") != mesh.end())
      fail(at + ".mesh", "a path inside the twin directory, got " + p.mesh);
    if (!std::filesystem::is_regular_file(twin_dir / p.mesh))
      fail(at + ".mesh", "no mesh file " + (twin_dir / p.mesh).string());
  }
  std::set<std::string> joints, children;
  std::map<std::string, std::string> parent_of;
  for (std::size_t i = 0; i < spec.joints.size(); ++i) {
    const auto& j = spec.joints[i];
    const std::string at = "joints[" + std::to_string(i) + "]";
    check_name(j.name, at + ".name");
    if (!joints.insert(j.name).second) fail(at + ".name", "a second joint named '" + j.name + "'");
    if (j.parent != "world" && !parts.count(j.parent))
      fail(at + ".parent", "no part named '" + j.parent + "' (nor 'world')");
    if (!parts.count(j.child)) fail(at + ".child", "no part named '" + j.child + "'");
    if (j.parent == j.child) fail(at + ".child", "a part cannot be jointed to itself");
    if (!children.insert(j.child).second)
      fail(at + ".child", "part '" + j.child + "' is already the child of another joint");
    if (Eigen::Vector3d(j.axis.data()).norm() < 1e-9) fail(at + ".axis", "a non-zero axis");
    parent_of[j.child] = j.parent;
  }
  for (const auto& [child, parent] : parent_of) {  // no cycles: every chain reaches the world
    std::string at = child;
    for (std::size_t steps = 0; parent_of.count(at); ++steps) {
      at = parent_of[at];
      if (steps > parent_of.size())
        fail("joints", "the joints form a loop through '" + child + "'");
    }
  }
  std::set<std::string> sites;
  for (std::size_t i = 0; i < spec.sites.size(); ++i) {
    const auto& s = spec.sites[i];
    const std::string at = "sites[" + std::to_string(i) + "]";
    check_name(s.name, at + ".name");
    if (!sites.insert(s.name).second) fail(at + ".name", "a second site named '" + s.name + "'");
    if (s.part != "world" && !parts.count(s.part))
      fail(at + ".part", "no part named '" + s.part + "' (nor 'world')");
  }
}

TwinSpec LoadTwinSpec(const std::filesystem::path& path) {
  TwinSpec spec = core::LoadConfig<TwinSpec>(path);
  ValidateTwinSpec(spec, path.parent_path(), path.string());
  return spec;
}

void SaveTwinSpec(const std::filesystem::path& path, const TwinSpec& spec, bool backup) {
  ValidateTwinSpec(spec, path.parent_path(), path.string());
  if (backup && std::filesystem::exists(path))
    std::filesystem::copy_file(path, path.string() + ".bak",
                               std::filesystem::copy_options::overwrite_existing);
  core::SaveConfig(path, spec);
}

}  // namespace twinforge::real2sim
