#include "real2sim/export.h"

#include <gtest/gtest.h>
#include <open3d/Open3D.h>

#include "core/test_support.h"
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

}  // namespace
}  // namespace twinforge::real2sim
