#include "real2sim/drawing.h"

#include <gtest/gtest.h>

#include <random>

#include "core/error.h"
#include "core/test_support.h"

namespace twinforge::real2sim {
namespace {

const std::filesystem::path kSpatulaScene =
    std::filesystem::path(TWINFORGE_ASSETS_DIR) / "tasks/spatula_flipping/scene.xml";

// The spatula's drawing is the twin scene's spatula body: handle, neck turned 45 deg, blade;
// its steel blade carries the centre of mass.
TEST(Drawing, ReadsABodysSolidsMassAndSites) {
  const Drawing d = ReadDrawing(kSpatulaScene, "spatula");
  ASSERT_EQ(d.solids.size(), 3u);
  EXPECT_NEAR(d.solids[0].size[0], 0.12, 1e-9) << "the handle's full length";
  EXPECT_NEAR(d.solids[1].euler[1], M_PI / 4, 1e-6) << "the neck's pitch";
  EXPECT_NEAR(d.solids[2].center[2], -0.043, 1e-9);
  EXPECT_NEAR(d.mass, 0.12, 1e-9);
  EXPECT_NEAR(d.com.x(), 0.06, 1e-9);
  ASSERT_EQ(d.sites.size(), 2u);
  EXPECT_EQ(d.sites[1].name, "blade_tip");
  EXPECT_NEAR(d.sites[1].at.x(), 0.12, 1e-9);
  EXPECT_NEAR(d.Depth(), 0.045, 1e-9) << "the blade's underside";
  EXPECT_EQ(d.Surface().triangles.size(), 36u);

  try {
    ReadDrawing(kSpatulaScene, "ladle");
    FAIL() << "no such body";
  } catch (const core::ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("ladle"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("scene.xml"), std::string::npos) << e.what();
  }
  EXPECT_THROW(ReadDrawing("/nonexistent/spatula.xml", "spatula"), core::IoError);
}

// A scan of the spatula lying on a table 2 cm below the base: what stands 8 mm or more above
// the table (the handle and the neck's top; the 3 mm blade is lost in the table), with 1 mm of
// noise.
std::vector<Eigen::Vector3d> ScanOf(const Drawing& d, const core::Pose& pose, double table,
                                    unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(0, 0.001);
  std::vector<Eigen::Vector3d> points;
  for (const auto& s : SampleSurface(d.Surface(), 6000, seed)) {
    const Eigen::Vector3d p = pose * s;
    if (p.z() - table < 0.008) continue;
    points.push_back(p + Eigen::Vector3d(noise(rng), noise(rng), noise(rng)));
  }
  return points;
}

// From the handle alone, the drawing is posed within a few mm and a degree or two, and never
// the wrong way round (the neck slopes down to where the blade must be).
TEST(Drawing, PosesTheWholeToolFromWhatTheScanShows) {
  const Drawing d = ReadDrawing(kSpatulaScene, "spatula");
  Plane table;
  table.offset = 0.02;  // z = -0.02
  int k = 0;
  for (double yaw : {0.3, 2.6, -1.9, -0.7}) {
    const core::Pose truth{Eigen::Vector3d(0.42 + 0.02 * k, -0.18, -0.02 + d.Depth()),
                           core::Yaw(yaw)};
    const auto points = ScanOf(d, truth, -0.02, 11 + k++);
    const DrawingFit fit = PoseDrawing(d, points, table);
    const double yaw_error =
        std::remainder(core::ToRollPitchYaw(fit.pose.rotation).z() - yaw, 2 * M_PI);
    EXPECT_LT((fit.pose.translation - truth.translation).norm(), 0.003) << "yaw " << yaw;
    EXPECT_LT(std::abs(yaw_error), 2 * M_PI / 180) << "yaw " << yaw;
    EXPECT_LT(fit.rms, 0.002) << "yaw " << yaw;
    EXPECT_GT(fit.coverage, 0.8) << "yaw " << yaw;
  }
  EXPECT_THROW(PoseDrawing(d, {}, table), core::Error);
}

}  // namespace
}  // namespace twinforge::real2sim
