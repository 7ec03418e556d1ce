#include "real2sim/export.h"

#include <gtest/gtest.h>
#include <open3d/Open3D.h>

#include <random>

#include "core/error.h"
#include "core/test_support.h"
#include "real2sim/drawing.h"
#include "real2sim/recipe.h"
#include "sim/mjcf.h"
#include "sim/model.h"
#include "sim/robot.h"

namespace twinforge::real2sim {
namespace {

// Boxes (corner, size) merged into one surface mesh.
Mesh Panels(const std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>>& boxes) {
  open3d::geometry::TriangleMesh all;
  for (const auto& [corner, size] : boxes) {
    auto box = open3d::geometry::TriangleMesh::CreateBox(size.x(), size.y(), size.z());
    box->Translate(corner);
    all += *box->SubdivideMidpoint(2);
  }
  return {all.vertices_, {}, all.triangles_};
}

// A chest open towards the robot (-x) with 1.5 cm panels, and a drawer in it: front and tray.
struct ChestTwin {
  std::filesystem::path dir;
  TwinSpec spec;
};

ChestTwin MakeChestTwin(const std::string& name) {
  ChestTwin t;
  t.dir = core::testing::TestDir("export", name);
  const double x0 = 0.65, w = 0.34, d = 0.32, h = 0.2, p = 0.015;
  WriteMesh(t.dir / "meshes/chest.ply",
            Panels({{{x0, -w / 2, 0}, {d, w, p}},                                 // bottom
                    {{x0, -w / 2, h - p}, {d, w, p}},                             // top
                    {{x0, -w / 2, p}, {d, p, h - 2 * p}},                         // right side
                    {{x0, w / 2 - p, p}, {d, p, h - 2 * p}},                      // left side
                    {{x0 + d - p, -w / 2 + p, p}, {p, w - 2 * p, h - 2 * p}}}));  // back
  WriteMesh(
      t.dir / "meshes/drawer.ply",
      Panels({{{x0 - 0.005, -w / 2 + p + 0.004, p + 0.004}, {p, w - 2 * p - 0.008, 0.15}},
              {{x0 + 0.01, -w / 2 + p + 0.01, p + 0.006}, {d - 0.04, w - 2 * p - 0.02, 0.01}}}));
  PartSpec chest;
  chest.name = "chest";
  chest.mesh = "meshes/chest.ply";
  chest.fixed = true;
  chest.mass = 6;
  PartSpec drawer;
  drawer.name = "drawer";
  drawer.mesh = "meshes/drawer.ply";
  drawer.mass = 1.0;
  JointSpec slide;
  slide.name = "drawer_slide";
  slide.parent = "chest";
  slide.child = "drawer";
  slide.axis = {-1, 0, 0};
  slide.range = {0, 0.25};
  slide.damping = 5;
  SiteSpec handle;
  handle.name = "drawer_handle";
  handle.part = "drawer";
  handle.position = {x0 - 0.03, 0, 0.1};
  t.spec.name = "chest_twin";
  t.spec.parts = {chest, drawer};
  t.spec.joints = {slide};
  t.spec.sites = {handle};
  return t;
}

sim::ModelPtr LoadWithRobot(const std::filesystem::path& scene) {
  sim::MjcfParts parts;
  parts.robot = sim::LoadRobotSpec(sim::DefaultRobotPath()).mjcf_path();
  parts.scene = scene;
  return sim::LoadModelFromText(sim::AssembleMjcf(parts), scene.string());
}

// The exported twin loads with the robot; the carcass is hollow (boxes, not a hull) and the
// drawer slides out under a pull and back in under a push, stopping at its limits.
TEST(Export, DrawerSlidesInItsHollowCarcass) {
  const ChestTwin t = MakeChestTwin("slide");
  const ExportReport report = ExportMjcf(t.spec, t.dir);
  EXPECT_GE(report.boxes.at("chest"), 5);
  const sim::ModelPtr m = LoadWithRobot(report.scene);
  const sim::DataPtr d = sim::MakeData(m.get());
  mj_forward(m.get(), d.get());

  // No chest collision box covers the middle of the cavity.
  const Eigen::Vector3d cavity(0.65 + 0.16, 0, 0.1);
  const int chest = mj_name2id(m.get(), mjOBJ_BODY, "chest");
  for (int g = 0; g < m->ngeom; ++g) {
    if (m->geom_bodyid[g] != chest || m->geom_type[g] != mjGEOM_BOX || m->geom_group[g] != 3)
      continue;
    const Eigen::Map<const Eigen::Matrix<mjtNum, 3, 3, Eigen::RowMajor>> r(d->geom_xmat + 9 * g);
    const Eigen::Vector3d local = r.transpose() * (cavity - Eigen::Vector3d(d->geom_xpos + 3 * g));
    bool inside = true;
    for (int k = 0; k < 3; ++k) inside &= std::abs(local[k]) < m->geom_size[3 * g + k];
    EXPECT_FALSE(inside) << "collision box " << g << " fills the cavity";
  }
  const int site = mj_name2id(m.get(), mjOBJ_SITE, "drawer_handle");
  ASSERT_GE(site, 0);
  EXPECT_NEAR(d->site_xpos[3 * site], 0.65 - 0.03, 1e-6);

  const int drawer = mj_name2id(m.get(), mjOBJ_BODY, "drawer");
  const int joint = mj_name2id(m.get(), mjOBJ_JOINT, "drawer_slide");
  const int qpos = m->jnt_qposadr[joint];
  // Hold the arm where it is (it is not part of this test).
  for (int i = 0; i < m->nu; ++i) d->ctrl[i] = 0;
  auto push = [&](double fx, double seconds) {
    for (int s = 0; s < int(seconds / m->opt.timestep); ++s) {
      d->xfrc_applied[6 * drawer] = fx;
      mj_step(m.get(), d.get());
    }
  };
  push(-40, 1.0);
  EXPECT_GT(d->qpos[qpos], 0.2) << "pulled out";
  EXPECT_LT(d->qpos[qpos], 0.26) << "stops at its limit";
  push(+40, 1.5);
  EXPECT_LT(d->qpos[qpos], 0.02) << "pushed back in";
  EXPECT_GT(d->qpos[qpos], -0.005);
  EXPECT_TRUE(std::isfinite(d->qacc[m->jnt_dofadr[joint]]));
}

TEST(Export, BoxCoverOfAHollowShellStaysHollow) {
  // The six faces of a 0.2 m cube, sampled densely.
  std::vector<Eigen::Vector3d> points, normals;
  for (int face = 0; face < 6; ++face)
    for (int i = 0; i <= 60; ++i)
      for (int j = 0; j <= 60; ++j) {
        Eigen::Vector3d p;
        p[face / 2] = face % 2 ? 0.1 : -0.1;
        p[(face / 2 + 1) % 3] = -0.1 + 0.2 * i / 60;
        p[(face / 2 + 2) % 3] = -0.1 + 0.2 * j / 60;
        points.push_back(p);
        Eigen::Vector3d n = Eigen::Vector3d::Zero();
        n[face / 2] = face % 2 ? 1 : -1;
        normals.push_back(n);
      }
  const auto boxes = CoverWithBoxes(points, normals, 0.01);
  ASSERT_FALSE(boxes.empty());
  EXPECT_LE(boxes.size(), 12u) << "a box or two per face";
  double volume = 0;
  for (const auto& b : boxes) {
    volume += 8 * b.half.prod();
    EXPECT_FALSE((b.centre.array().abs() < b.half.array()).all()) << "a box covers the centre";
  }
  EXPECT_LT(volume, 0.5 * 0.2 * 0.2 * 0.2) << "a shell, not a solid";
}

// A scan's blur: every vertex moved by Gaussian noise of `sigma` m per axis.
Mesh Blurred(Mesh mesh, double sigma, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(0, sigma);
  for (auto& v : mesh.vertices) v += Eigen::Vector3d(noise(rng), noise(rng), noise(rng));
  return mesh;
}

// Runs the scene `seconds` with the arm held; returns the body's position and the cosine of its
// tilt from upright.
std::pair<Eigen::Vector3d, double> Settle(const sim::ModelPtr& m, const sim::DataPtr& d,
                                          const char* body, double seconds) {
  for (int i = 0; i < m->nu; ++i) d->ctrl[i] = 0;
  for (int s = 0; s < int(seconds / m->opt.timestep); ++s) mj_step(m.get(), d.get());
  const int b = mj_name2id(m.get(), mjOBJ_BODY, body);
  return {Eigen::Vector3d(d->xpos + 3 * b), d->xmat[9 * b + 8]};
}

// A proposed spec of one segment, object_0, whose mesh is `mesh` (under the twin directory).
TwinSpec OneSegment(const std::string& mesh) {
  TwinSpec spec;
  spec.parts.resize(1);
  spec.parts[0].name = "object_0";
  spec.parts[0].mesh = mesh;
  return spec;
}

// A recipe part that collides as a solid fitted to its scan.
sim::TwinPartRecipe FittedPart(const char* name, const std::array<double, 3>& size,
                               const char* shape, double mass) {
  sim::TwinPartRecipe part;
  part.name = name;
  part.size = size;
  part.shape = shape;
  part.mass = mass;
  return part;
}

// A 2 cm peg and a block with a hole 1.5 mm wider a side, scanned with a mm of noise. Fitted
// as boxes (recipe shape "box", the block with the drawing's hole through it), the peg set on
// the hole goes down it.
TEST(Export, APegGoesDownTheHoleOfItsFittedBlock) {
  const auto dir = core::testing::TestDir("export", "peg");
  const double side = 0.063, hole = 0.023, wall = 0.5 * (side - hole), h = 0.04;
  const double bx = 0.5 - side / 2, by = 0.15 - side / 2;
  WriteMesh(dir / "meshes/block.ply",
            Blurred(Panels({{{bx, by, 0}, {wall, side, h}},
                            {{bx + side - wall, by, 0}, {wall, side, h}},
                            {{bx + wall, by, 0}, {hole, wall, h}},
                            {{bx + wall, by + side - wall, 0}, {hole, wall, h}}}),
                    0.001, 1));
  WriteMesh(dir / "meshes/peg.ply",
            Blurred(Panels({{{0.49, -0.21, 0}, {0.02, 0.02, 0.09}}}), 0.001, 2));
  TwinSpec spec;
  for (const char* name : {"block", "peg"}) {
    PartSpec part;
    part.name = std::string("object_") + name;
    part.mesh = std::string("meshes/") + name + ".ply";
    spec.parts.push_back(part);
  }
  sim::TwinRecipe recipe;
  recipe.parts = {FittedPart("peg", {0.02, 0.02, 0.09}, "box", 0.06),
                  FittedPart("hole_block", {0.063, 0.063, 0.04}, "box", 1.2)};
  recipe.parts[1].hole = {hole, hole, 0};
  recipe.sites.resize(2);
  recipe.sites[0].name = "peg_tip";
  recipe.sites[0].part = "peg";
  recipe.sites[0].box = {0, 0, -1};
  recipe.sites[1].name = "hole_top";
  recipe.sites[1].part = "hole_block";
  recipe.sites[1].box = {0, 0, 1};
  ApplyRecipe(spec, recipe, dir, "test recipe");
  ASSERT_EQ(spec.parts[1].name, "peg");
  EXPECT_EQ(spec.parts[1].collision, PartSpec::Collision::kSolids);
  EXPECT_EQ(spec.parts[0].boxes.size(), 4u) << "four walls around a hole through";
  const ExportReport report = ExportMjcf(spec, dir);
  EXPECT_EQ(report.boxes.at("peg"), 0) << "no boxes over the scan";

  const sim::ModelPtr m = LoadWithRobot(report.scene);
  const sim::DataPtr d = sim::MakeData(m.get());
  mj_forward(m.get(), d.get());
  const int tip = mj_name2id(m.get(), mjOBJ_SITE, "peg_tip");
  const int top = mj_name2id(m.get(), mjOBJ_SITE, "hole_top");
  // The peg's tip 1 cm over the hole.
  const int peg = m->jnt_qposadr[mj_name2id(m.get(), mjOBJ_JOINT, "peg_free")];
  for (int k = 0; k < 3; ++k)
    d->qpos[peg + k] += d->site_xpos[3 * top + k] - d->site_xpos[3 * tip + k] + (k == 2) * 0.01;
  mj_forward(m.get(), d.get());
  Settle(m, d, "peg", 1.0);
  EXPECT_LT(d->site_xpos[3 * tip + 2], d->site_xpos[3 * top + 2] - 0.03) << "down the hole";
  EXPECT_LT(std::hypot(d->site_xpos[3 * tip] - d->site_xpos[3 * top],
                       d->site_xpos[3 * tip + 1] - d->site_xpos[3 * top + 1]),
            0.003);
}

// A mug's body fitted as a cylinder (recipe shape "cylinder") stands where it is set down:
// MuJoCo 2.2 gives a cylinder one contact with the table, so it stands on a thin box.
TEST(Export, AFittedCylinderStandsStill) {
  const auto dir = core::testing::TestDir("export", "cylinder");
  auto cylinder = open3d::geometry::TriangleMesh::CreateCylinder(0.04, 0.09, 40, 8);
  cylinder->Translate(Eigen::Vector3d(0.5, -0.15, 0.045));
  WriteMesh(dir / "meshes/mug.ply",
            Blurred({cylinder->vertices_, {}, cylinder->triangles_}, 0.001, 3));
  TwinSpec spec = OneSegment("meshes/mug.ply");
  sim::TwinRecipe recipe;
  recipe.parts = {FittedPart("mug", {0.08, 0.08, 0.09}, "cylinder", 0.3)};
  ApplyRecipe(spec, recipe, dir, "test recipe");
  ASSERT_EQ(spec.parts[0].boxes.size(), 1u);
  EXPECT_NEAR(spec.parts[0].boxes[0].size[0], 0.08, 0.002);
  const sim::ModelPtr m = LoadWithRobot(ExportMjcf(spec, dir).scene);
  const sim::DataPtr d = sim::MakeData(m.get());
  const int mug = m->jnt_qposadr[mj_name2id(m.get(), mjOBJ_JOINT, "mug_free")];
  // Let go of 1.5 cm over the table, tilted 3 deg, as a gripper lets go of it.
  const Eigen::Vector3d start(d->qpos + mug);
  d->qpos[mug + 2] += 0.015;
  const core::Quat tilt = core::AxisAngle(Eigen::Vector3d::UnitX(), 3 * M_PI / 180);
  core::QuatToMj(core::QuatFromMj(d->qpos + mug + 3) * tilt, d->qpos + mug + 3);
  mj_forward(m.get(), d.get());
  const auto [at, upright] = Settle(m, d, "mug", 1.5);
  EXPECT_GT(upright, std::cos(0.5 * M_PI / 180)) << "tilted";
  EXPECT_LT((at - start).head<2>().norm(), 0.003) << "slid or rolled";
}

// A spatula the scan shows only the handle of, drawn (recipe shape "drawing") from the task's
// drawing: the twin has the whole tool and its sites where the real one has them, and with its
// mass on the steel blade, as drawn, it rests on the blade with the handle up. Spread evenly
// over its bounds, the same mass tips it onto the handle.
TEST(Export, ADrawnSpatulaRestsOnItsBlade) {
  const auto dir = core::testing::TestDir("export", "drawn");
  const auto task =
      std::filesystem::path(TWINFORGE_ASSETS_DIR) / "tasks/spatula_flipping/task.yaml";
  const Drawing drawing = ReadDrawing(task.parent_path() / "scene.xml", "spatula");
  const core::Pose truth{Eigen::Vector3d(0.4, -0.2, drawing.Depth()), core::Yaw(0.4)};
  auto handle = open3d::geometry::TriangleMesh::CreateBox(0.12, 0.02, 0.016);
  handle->Translate(Eigen::Vector3d(-0.12, -0.01, -0.008));
  handle = handle->SubdivideMidpoint(3);
  handle->Transform(truth.Matrix());
  WriteMesh(dir / "meshes/handle.ply",
            Blurred({handle->vertices_, {}, handle->triangles_}, 0.001, 4));
  TwinSpec spec = OneSegment("meshes/handle.ply");
  sim::TwinRecipe recipe;
  recipe.parts = {FittedPart("spatula", {0.12, 0.02, 0.02}, "drawing", 0)};
  recipe.parts[0].drawing = "scene.xml";
  ApplyRecipe(spec, recipe, dir, task);
  ASSERT_EQ(spec.parts[0].name, "spatula");
  EXPECT_EQ(spec.parts[0].boxes.size(), 3u);
  EXPECT_NEAR(spec.parts[0].mass, 0.12, 1e-9);
  ASSERT_TRUE(spec.parts[0].com.has_value());
  ASSERT_EQ(spec.sites.size(), 2u);
  const Eigen::Vector3d tip(spec.sites[1].position.data());
  EXPECT_EQ(spec.sites[1].name, "blade_tip");
  EXPECT_LT((tip - truth * drawing.sites[1].at).norm(), 0.004) << "the blade's tip, never seen";

  auto settle = [&](const TwinSpec& twin) {
    const sim::ModelPtr m = LoadWithRobot(ExportMjcf(twin, dir).scene);
    const sim::DataPtr d = sim::MakeData(m.get());
    mj_forward(m.get(), d.get());
    Settle(m, d, "spatula", 1.0);
    return d->site_xpos[3 * mj_name2id(m.get(), mjOBJ_SITE, "spatula_grasp") + 2];
  };
  EXPECT_GT(settle(spec), 0.04) << "the handle stays 4.5 cm up";
  TwinSpec even = spec;
  even.parts[0].com.reset();
  EXPECT_LT(settle(even), 0.03) << "without the blade's weight it tips onto the handle";
}

// A part standing on another is carved out of a part the recipe names that has its own segment;
// anything else is refused, naming the field.
TEST(Export, APartOnAnotherNeedsACarrierWithItsOwnSegment) {
  const auto dir = core::testing::TestDir("export", "on");
  WriteMesh(dir / "meshes/block.ply", Panels({{{0.5, 0, 0}, {0.1, 0.1, 0.05}}}));
  TwinSpec spec = OneSegment("meshes/block.ply");
  sim::TwinRecipe recipe;
  recipe.parts = {FittedPart("griddle", {0.1, 0.1, 0.05}, "box", 1),
                  FittedPart("pancake", {0.08, 0.08, 0.01}, "cylinder", 0.05)};
  recipe.parts[1].on = "grill";
  try {
    TwinSpec twin = spec;
    ApplyRecipe(twin, recipe, dir, "spatula.yaml");
    FAIL() << "no part 'grill'";
  } catch (const core::ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("twin.parts[1].on"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("grill"), std::string::npos) << e.what();
  }
  recipe.parts[1].on = "griddle";
  EXPECT_THROW(ApplyRecipe(spec, recipe, dir, "spatula.yaml"), core::ConfigError)
      << "nothing stands on a bare block's top";
}

// A light pancake on a dark griddle, its edge against the griddle's lip, as high as the
// pancake: the scan fuses the two, and the lip beside the pancake stands on the top as the
// pancake does. The colours tell them apart: the pancake's cylinder is fitted to the pancake.
TEST(Export, WhatStandsOnTopInTheCarriersColourStaysWithTheCarrier) {
  const auto dir = core::testing::TestDir("export", "lip");
  const Eigen::Vector3d pancake(0.583, 0, 0.026 + 0.0055);
  const double radius = 0.044;
  Mesh scan;
  auto add = [&](const Mesh& part, const Eigen::Vector3d& colour) {
    const std::size_t first = scan.vertices.size();
    for (const auto& v : part.vertices) {
      scan.vertices.push_back(v);
      scan.colors.push_back(colour);
    }
    for (const auto& t : part.triangles)
      scan.triangles.push_back(t + Eigen::Vector3i::Constant(static_cast<int>(first)));
  };
  const Eigen::Vector3d iron(0.09, 0.09, 0.1), batter(0.8, 0.65, 0.35);
  add(Panels({{{0.55, -0.11, 0}, {0.2, 0.22, 0.026}}}), iron);       // the griddle
  add(Panels({{{0.626, -0.08, 0.026}, {0.01, 0.16, 0.01}}}), iron);  // its lip, at the pancake
  // The fusion fills the corners between the pancake's edge and the lip, at the lip's height.
  add(Panels({{{0.60, -0.035, 0.026}, {0.026, 0.07, 0.0095}}}), iron);
  auto disc = open3d::geometry::TriangleMesh::CreateCylinder(radius, 0.011, 48, 2);
  disc->Translate(pancake);
  add({disc->vertices_, {}, disc->triangles_}, batter);
  sim::TwinRecipe recipe;
  recipe.parts = {FittedPart("griddle", {0.2, 0.22, 0.036}, "box", 1),
                  FittedPart("pancake", {0.08, 0.08, 0.006}, "cylinder", 0.05)};
  recipe.parts[1].on = "griddle";
  // The pancake part's mesh (what the twin draws and the calibration moves): how far it
  // reaches past the pancake's edge towards the lip; and its cylinder's centre.
  struct Carved {
    double reach, off, width;
  };
  auto carve = [&](const Mesh& mesh) {
    WriteMesh(dir / "meshes/griddle.ply", mesh);
    TwinSpec spec = OneSegment("meshes/griddle.ply");
    ApplyRecipe(spec, recipe, dir, "spatula.yaml");
    const auto part = std::find_if(spec.parts.begin(), spec.parts.end(),
                                   [](const PartSpec& p) { return p.name == "pancake"; });
    EXPECT_NE(part, spec.parts.end());
    double far = -1;
    for (const auto& v : ReadMesh(dir / part->mesh).vertices) far = std::max(far, v.x());
    const BoxSpec& cylinder = part->boxes.at(0);
    const Carved c{
        far - (pancake.x() + radius),
        (Eigen::Vector2d(cylinder.center[0], cylinder.center[1]) - pancake.head<2>()).norm(),
        cylinder.size[0]};
    std::printf(
        "pancake %s colours: mesh %.1f mm past its edge; cylinder %.1f mm off, %.1f mm "
        "wide (%.1f)\n",
        mesh.colors.empty() ? "without" : "with", 1000 * c.reach, 1000 * c.off, 1000 * c.width,
        2000 * radius);
    return c;
  };
  const Mesh blurred = Blurred(scan, 0.0007, 4);
  const Carved coloured = carve(blurred);
  EXPECT_LT(coloured.reach, 0.002);
  EXPECT_LT(coloured.off, 0.0015);
  EXPECT_NEAR(coloured.width, 2 * radius, 0.003);
  Mesh grey = blurred;
  grey.colors.clear();
  EXPECT_GT(carve(grey).reach, 0.008) << "the lip is not the pancake's by its shape alone";
}

}  // namespace
}  // namespace twinforge::real2sim
