// The twin spec (twin.yaml): what a person decides about a scan, and everything the MJCF export
// needs. Parts are made from mesh pieces and box cuts (as in RialTo's editor); joints connect
// them; sites name the points task success reads.
//
//   name: drawer_twin
//   parts:
//     - name: chest
//       mesh: meshes/fixture_0.ply          # relative to the twin directory
//       cuts: [{op: subtract, box: {center: [0.62, 0, 0.1], size: [0.05, 0.3, 0.16]}}]
//       fixed: true                         # welded to the world
//     - name: drawer
//       mesh: meshes/fixture_0.ply
//       cuts: [{op: intersect, box: {center: [0.62, 0, 0.1], size: [0.05, 0.3, 0.16]}}]
//       mass: 1.2
//   joints:
//     - {name: drawer_slide, type: prismatic, parent: chest, child: drawer, axis: [-1, 0, 0],
//        range: [0, 0.25], damping: 10}
//   sites:
//     - {name: drawer_handle, part: drawer, position: [0.55, 0, 0.15]}
//
// All positions are in the robot base frame of the scan (the twin is built where it was seen).
// A part that is no joint's child and not `fixed` is a free body (a movable object).
#pragma once

#include <array>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "core/config.h"
#include "core/se3.h"
#include "real2sim/mesh.h"

namespace twinforge::real2sim {

enum class SolidShape { kBox, kCylinder };

// A box, or the upright cylinder inscribed in it (along the box's z; diameter size[0], which
// must equal size[1]).
struct BoxSpec {
  std::array<double, 3> center{0, 0, 0};
  std::array<double, 3> size{0.1, 0.1, 0.1};  // full edge lengths, m
  std::array<double, 3> euler{0, 0, 0};       // rad, roll/pitch/yaw
  SolidShape shape = SolidShape::kBox;
  bool hidden = false;  // (a part's solid) collided with, not drawn: fitted to what is seen
  template <class A>
  void Serialize(A& a) {
    a("center", center);
    a("size", size);
    a("euler", euler);
    a.Enum("shape", shape, {{"box", SolidShape::kBox}, {"cylinder", SolidShape::kCylinder}});
    a("hidden", hidden);
    a.Require(size[0] > 0 && size[1] > 0 && size[2] > 0, "size", "three positive lengths in m");
    a.Require(shape == SolidShape::kBox || std::abs(size[0] - size[1]) < 1e-9, "size",
              "a cylinder's diameter twice: [d, d, height]");
  }
  core::Pose pose() const;  // box frame -> base
  bool Contains(const Eigen::Vector3d& p) const;
};

enum class CutOp { kSubtract, kIntersect };

struct CutSpec {
  CutOp op = CutOp::kSubtract;  // subtract: keep what is outside the box; intersect: inside
  BoxSpec box;
  template <class A>
  void Serialize(A& a) {
    a.Enum("op", op, {{"subtract", CutOp::kSubtract}, {"intersect", CutOp::kIntersect}});
    a("box", box);
  }
};

struct PartSpec {
  std::string name;
  std::string mesh;  // PLY/OBJ relative to the twin directory
  std::vector<CutSpec> cuts;
  bool fixed = false;
  double mass = 0.5;  // kg
  double friction = 0.8;
  std::array<double, 4> rgba{0, 0, 0, 0};  // 0 alpha: vertex colours of the mesh
  // Solid boxes added to the part (base frame), seen and collided with: what a scan shows
  // poorly, e.g. a shiny handle bar the depth sensor lost.
  std::vector<BoxSpec> boxes;
  // What the part collides with: "scan", boxes fitted to its scanned surface, plus `boxes`; or
  // "solids", `boxes` alone: where the scan's few mm of blur matter (a peg and its hole), solids
  // fitted to the scan (hidden: the scan is what is seen).
  enum class Collision { kScan, kSolids } collision = Collision::kScan;
  // The centre of mass (base frame), where the mass is not spread evenly over the bounds: a
  // drawn spatula's steel blade. None: the middle of the part's bounds.
  std::optional<std::array<double, 3>> com;
  template <class A>
  void Serialize(A& a) {
    a("name", name);
    a("mesh", mesh);
    a("cuts", cuts);
    a("boxes", boxes);
    a.Enum("collision", collision, {{"scan", Collision::kScan}, {"solids", Collision::kSolids}});
    a.Require(collision == Collision::kScan || !boxes.empty(), "collision",
              "\"scan\", or \"solids\" with at least one of `boxes`");
    a("fixed", fixed);
    a("mass", mass);
    a("friction", friction);
    a("rgba", rgba);
    a("com", com);
    a.Require(!name.empty(), "name", "a part name");
    a.Require(!mesh.empty(), "mesh", "a mesh file");
    a.Require(mass > 0, "mass", "a positive mass in kg");
    a.Require(friction > 0, "friction", "a positive friction coefficient");
  }
};

enum class JointType { kFixed, kPrismatic, kRevolute };
const char* ToString(JointType type);  // "fixed", "prismatic", "revolute" (as in twin.yaml)

struct JointSpec {
  std::string name;
  JointType type = JointType::kPrismatic;
  std::string parent, child;  // part names; parent "world" for a joint to the static scene
  std::array<double, 3> axis{1, 0, 0};
  std::array<double, 3> origin{0, 0, 0};  // a point on the axis (revolute), base frame
  std::array<double, 2> range{0, 0.2};    // m or rad
  double damping = 5;
  double frictionloss = 0;
  template <class A>
  void Serialize(A& a) {
    a("name", name);
    a.Enum("type", type,
           {{"fixed", JointType::kFixed},
            {"prismatic", JointType::kPrismatic},
            {"revolute", JointType::kRevolute}});
    a("parent", parent);
    a("child", child);
    a("axis", axis);
    a("origin", origin);
    a("range", range);
    a("damping", damping);
    a("frictionloss", frictionloss);
    a.Require(!name.empty(), "name", "a joint name");
    a.Require(range[0] < range[1], "range", "[lower, upper] with lower < upper");
    a.Require(damping >= 0 && frictionloss >= 0, "damping", "non-negative damping and friction");
  }
};

struct SiteSpec {
  std::string name;
  std::string part;
  std::array<double, 3> position{0, 0, 0};  // base frame
  double yaw = 0;  // rad about +z: where the site's x points (task steps read the site's frame)
  template <class A>
  void Serialize(A& a) {
    a("name", name);
    a("part", part);
    a("position", position);
    a("yaw", yaw);
    a.Require(!name.empty(), "name", "a site name");
  }
};

struct TwinSpec {
  std::string name = "twin";
  std::vector<PartSpec> parts;
  std::vector<JointSpec> joints;
  std::vector<SiteSpec> sites;
  std::array<double, 4> support{0, 0, 1, 0};  // the table plane n.x + d = 0
  template <class A>
  void Serialize(A& a) {
    a("name", name);
    a("parts", parts);
    a("joints", joints);
    a("sites", sites);
    a("support", support);
  }
};

// The table plane the spec's scene stands on.
Plane SupportOf(const TwinSpec& spec);

// A cut: the triangles whose centroid is outside (subtract) or inside (intersect) the box.
// Cutting the same mesh both ways splits it into two pieces that together are the whole.
Mesh CutMesh(const Mesh& mesh, const CutSpec& cut);
// A part's mesh: its file (under `twin_dir`) with its cuts applied in order.
Mesh PartMesh(const PartSpec& part, const std::filesystem::path& twin_dir);

// A box's surface as a closed mesh (12 triangles, outward), base frame.
Mesh BoxMesh(const BoxSpec& box);

// Moves by `motion` (base frame) what the spec places with the parts named, as when the object a
// mesh shows turns out to stand elsewhere (the caller moves the mesh file): their cuts, boxes and
// centres of mass, the sites on them, and the joints whose child they are (the axis turned, the
// origin moved). Returns the parts moved.
int MoveParts(TwinSpec& spec, const std::vector<std::string>& parts, const core::Pose& motion);
// The parts made from the mesh file `mesh` (as the parts name it).
std::vector<std::string> PartsOfMesh(const TwinSpec& spec, const std::string& mesh);

// Loads and validates twin.yaml. Throws ConfigError naming the file and field.
TwinSpec LoadTwinSpec(const std::filesystem::path& path);
// Cross-field checks (names of letters, digits, '_', '-' and '.', unique; references resolve;
// one parent per part; axes non-zero; mesh files exist under `twin_dir`, by relative paths that
// stay inside it). Throws ConfigError naming `origin` and the field path,
// e.g. "joints[0].child".
void ValidateTwinSpec(const TwinSpec& spec, const std::filesystem::path& twin_dir,
                      const std::string& origin);
// Writes twin.yaml atomically, keeping the previous file as twin.yaml.bak (unless `backup` is
// false: an editor that already kept the file it started from).
void SaveTwinSpec(const std::filesystem::path& path, const TwinSpec& spec, bool backup = true);

}  // namespace twinforge::real2sim
