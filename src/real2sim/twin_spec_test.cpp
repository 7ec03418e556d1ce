#include "real2sim/twin_spec.h"

#include <gtest/gtest.h>
#include <open3d/Open3D.h>

#include <fstream>
#include <map>

#include "core/test_support.h"

namespace twinforge::real2sim {
namespace {

std::filesystem::path TwinDir(const std::string& name) {
  const auto dir = core::testing::TestDir("twin_spec", name);
  std::filesystem::create_directories(dir / "meshes");
  return dir;
}

// A closed box surface 0.3 x 0.3 x 0.2 with its corner at (0.5, -0.15, 0), finely triangulated.
Mesh ChestMesh() {
  auto box = open3d::geometry::TriangleMesh::CreateBox(0.3, 0.3, 0.2);
  box->Translate(Eigen::Vector3d(0.5, -0.15, 0));
  box = box->SubdivideMidpoint(4);
  return {box->vertices_, {}, box->triangles_};
}

void WriteText(const std::filesystem::path& path, const std::string& text) {
  std::ofstream(path) << text;
}

const char* kSpec = R"(name: chest_twin
parts:
  - {name: chest, mesh: meshes/chest.ply, fixed: true,
     cuts: [{op: subtract, box: {center: [0.5, 0, 0.1], size: [0.1, 0.26, 0.16]}}]}
  - {name: drawer, mesh: meshes/chest.ply, mass: 1.2,
     cuts: [{op: intersect, box: {center: [0.5, 0, 0.1], size: [0.1, 0.26, 0.16]}}]}
joints:
  - {name: drawer_slide, type: prismatic, parent: chest, child: drawer, axis: [-1, 0, 0],
     range: [0, 0.25]}
sites:
  - {name: drawer_handle, part: drawer, position: [0.48, 0, 0.15]}
)";

TEST(TwinSpec, LoadsSavesAndKeepsABackup) {
  const auto dir = TwinDir("round_trip");
  WriteMesh(dir / "meshes/chest.ply", ChestMesh());
  WriteText(dir / "twin.yaml", kSpec);
  TwinSpec spec = LoadTwinSpec(dir / "twin.yaml");
  ASSERT_EQ(spec.parts.size(), 2u);
  EXPECT_EQ(spec.joints[0].type, JointType::kPrismatic);
  EXPECT_EQ(spec.parts[1].cuts[0].op, CutOp::kIntersect);
  spec.parts[1].mass = 2.0;
  SaveTwinSpec(dir / "twin.yaml", spec);
  EXPECT_TRUE(std::filesystem::exists(dir / "twin.yaml.bak"));
  EXPECT_EQ(LoadTwinSpec(dir / "twin.yaml").parts[1].mass, 2.0);
  EXPECT_EQ(LoadTwinSpec(dir / "twin.yaml.bak").parts[1].mass, 1.2);
}

// A cut splits a mesh in two: nothing lost, nothing shared, and each piece is open only along
// the cut (its boundary edges lie on the cut box's surface).
TEST(TwinSpec, ACutMakesTwoPiecesOpenOnlyAlongTheCut) {
  const auto dir = TwinDir("cut");
  WriteMesh(dir / "meshes/chest.ply", ChestMesh());
  WriteText(dir / "twin.yaml", kSpec);
  const TwinSpec spec = LoadTwinSpec(dir / "twin.yaml");
  const Mesh whole = ReadMesh(dir / "meshes/chest.ply");
  const Mesh chest = PartMesh(spec.parts[0], dir), drawer = PartMesh(spec.parts[1], dir);
  ASSERT_FALSE(chest.empty());
  ASSERT_FALSE(drawer.empty());
  EXPECT_EQ(chest.triangles.size() + drawer.triangles.size(), whole.triangles.size());
  EXPECT_NEAR(chest.Area() + drawer.Area(), whole.Area(), 1e-9);
  EXPECT_NEAR(drawer.Area(), 0.26 * 0.16, 0.01) << "the front panel under the cut box";

  const BoxSpec& box = spec.parts[0].cuts[0].box;
  auto open_edges_off_the_cut = [&](const Mesh& m) {
    std::map<std::pair<int, int>, int> uses;
    for (const auto& t : m.triangles)
      for (int c = 0; c < 3; ++c) {
        const int a = t[c], b = t[(c + 1) % 3];
        ++uses[{std::min(a, b), std::max(a, b)}];
      }
    int open = 0, off = 0;
    const double cell = 0.3 / 16;  // the subdivided triangles' size
    for (const auto& [edge, n] : uses) {
      if (n != 1) continue;
      ++open;
      const Eigen::Vector3d mid =
          box.pose().Inverse() * (0.5 * (m.vertices[edge.first] + m.vertices[edge.second]));
      double to_surface = 1e9;
      for (int i = 0; i < 3; ++i)
        to_surface = std::min(to_surface, std::abs(std::abs(mid[i]) - 0.5 * box.size[i]));
      off += to_surface > 1.5 * cell;
    }
    return std::make_pair(open, off);
  };
  const auto [chest_open, chest_off] = open_edges_off_the_cut(chest);
  const auto [drawer_open, drawer_off] = open_edges_off_the_cut(drawer);
  EXPECT_GT(chest_open, 0);
  EXPECT_EQ(chest_off, 0);
  EXPECT_EQ(drawer_off, 0);
  EXPECT_EQ(open_edges_off_the_cut(whole).first, 0) << "the uncut box is closed";
}

// Every broken reference is named by file and field.
// An object found to stand elsewhere: moving its mesh and the spec's parts of it together
// keeps every cut on the same triangles, and its joint and sites go with it; another object's
// stay.
TEST(TwinSpec, WhatIsPlacedWithAMeshMovesWithIt) {
  const auto dir = TwinDir("move");
  WriteMesh(dir / "meshes/chest.ply", ChestMesh());
  WriteText(dir / "twin.yaml", kSpec);
  TwinSpec spec = LoadTwinSpec(dir / "twin.yaml");
  spec.parts.push_back(spec.parts[1]);
  spec.parts.back().name = "peg";
  spec.parts.back().mesh = "meshes/peg.ply";
  spec.parts.back().com = std::array<double, 3>{0.3, 0.2, 0.05};
  spec.sites.push_back({"peg_tip", "peg", {0.3, 0.2, 0.1}, 0.5});
  const Mesh drawer_before = PartMesh(spec.parts[1], dir);

  // A quarter turn about z through (0.65, 0, 0) and 1 cm up.
  const core::Quat quarter = core::Yaw(M_PI / 2);
  const Eigen::Vector3d pivot(0.65, 0, 0);
  const core::Pose motion{pivot + Eigen::Vector3d(0, 0, 0.01) - quarter * pivot, quarter};
  const TwinSpec before = spec;
  EXPECT_EQ(MoveParts(spec, PartsOfMesh(spec, "meshes/chest.ply"), motion), 2);
  Mesh moved = ReadMesh(dir / "meshes/chest.ply");
  for (auto& v : moved.vertices) v = motion * v;
  WriteMesh(dir / "meshes/chest.ply", moved);

  const Mesh drawer_after = PartMesh(spec.parts[1], dir);
  ASSERT_EQ(drawer_after.triangles.size(), drawer_before.triangles.size());
  EXPECT_NEAR(drawer_after.Area(), drawer_before.Area(), 1e-9);
  const Eigen::Vector3d axis(spec.joints[0].axis.data());
  EXPECT_TRUE(axis.isApprox(Eigen::Vector3d(0, -1, 0), 1e-9)) << axis.transpose();
  const Eigen::Vector3d handle(spec.sites[0].position.data());
  EXPECT_TRUE(handle.isApprox(Eigen::Vector3d(0.65, -0.17, 0.16), 1e-9)) << handle.transpose();
  EXPECT_NEAR(spec.sites[0].yaw, M_PI / 2, 1e-9);
  // The other object's part and site did not move.
  EXPECT_EQ(spec.parts[2].cuts[0].box.center, before.parts[2].cuts[0].box.center);
  EXPECT_EQ(*spec.parts[2].com, *before.parts[2].com);
  EXPECT_EQ(spec.sites[1].position, before.sites[1].position);
  EXPECT_EQ(spec.sites[1].yaw, 0.5);
}

TEST(TwinSpec, ErrorsNameTheFileAndField) {
  const auto dir = TwinDir("errors");
  WriteMesh(dir / "meshes/chest.ply", ChestMesh());
  auto error = [&](const std::string& from, const std::string& to) {
    std::string text = kSpec;
    const auto at = text.find(from);
    EXPECT_NE(at, std::string::npos) << from;
    text.replace(at, from.size(), to);
    WriteText(dir / "twin.yaml", text);
    try {
      LoadTwinSpec(dir / "twin.yaml");
    } catch (const core::ConfigError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  auto expect = [](const std::string& what, const std::string& field) {
    EXPECT_NE(what.find("twin.yaml"), std::string::npos) << what;
    EXPECT_NE(what.find(field), std::string::npos) << what;
  };
  expect(error("child: drawer", "child: drawr"), "joints[0].child");
  expect(error("part: drawer", "part: lid"), "sites[0].part");
  expect(error("{name: drawer, mesh", "{name: chest, mesh"), "parts[1].name");
  expect(error("mass: 1.2", "mass: -1"), "parts[1].mass");
  expect(error("range: [0, 0.25]", "range: [0.3, 0.25]"), "joints[0].range");
  expect(error("type: prismatic", "type: ball"), "joints[0].type");
  expect(error("axis: [-1, 0, 0]", "axis: [0, 0, 0]"), "joints[0].axis");
  expect(error("mesh: meshes/chest.ply, mass", "mesh: meshes/gone.ply, mass"), "parts[1].mesh");
  expect(error("op: subtract", "op: carve"), "parts[0].cuts[0].op");
}

}  // namespace
}  // namespace twinforge::real2sim
