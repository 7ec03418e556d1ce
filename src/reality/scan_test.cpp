#include "reality/scan.h"

#include <gtest/gtest.h>

#include <fstream>

#include "core/error.h"
#include "core/image.h"
#include "core/test_support.h"
#include "reality/proxy_reality.h"

namespace twinforge::reality {
namespace {

std::filesystem::path TempDir(const std::string& name) {
  return core::testing::TestDir("scan_test", name);
}

TEST(ScanPath, LooksAtTheSceneFromRingsAroundIt) {
  const sim::TaskSpec task = sim::LoadTaskSpec("open_drawer");
  ScanOptions options;
  const auto path = ScanPath(task, options);
  ASSERT_EQ(path.size(), 24u);
  const Eigen::Vector3d center(task.camera.look_at.data());
  const double radius = (Eigen::Vector3d(task.camera.position.data()) - center).norm();
  double min_y = 1e9, max_y = -1e9;
  for (const auto& pose : path) {
    EXPECT_NEAR((pose.translation - center).norm(), radius, 1e-9);
    // The optical axis (camera z) points at the scene centre.
    const Eigen::Vector3d axis = pose.rotation * Eigen::Vector3d::UnitZ();
    EXPECT_GT(axis.dot((center - pose.translation).normalized()), 0.9999);
    EXPECT_GT(pose.translation.z(), center.z());
    min_y = std::min(min_y, pose.translation.y());
    max_y = std::max(max_y, pose.translation.y());
  }
  EXPECT_GT(max_y - min_y, radius) << "views from both sides";
}

TEST(Scan, WritesFramesTheLayoutDescribesAndReadsThemBack) {
  ProxyReality proxy(ResolveWorldDir("open_drawer"));
  proxy.Reset({2, 1});
  ScanOptions options;
  options.width = 96;
  options.height = 72;
  options.frames_per_ring = 3;
  const auto path = ScanPath(sim::LoadTaskSpec("open_drawer"), options);
  const auto dir = TempDir("written");
  const core::Scan written = CaptureScan(proxy, path, ScanIntrinsics(options), dir);
  ASSERT_EQ(written.frames.size(), 6u);
  for (const char* file : {"intrinsic.json", "trajectory.json", "trajectory.log", "frames.json"})
    EXPECT_TRUE(std::filesystem::is_regular_file(dir / file)) << file;

  const core::Scan scan = core::ReadScan(dir);
  ASSERT_EQ(scan.frames.size(), 6u);
  EXPECT_EQ(scan.source, "proxy:open_drawer");
  EXPECT_EQ(scan.depth_scale, 1000.0);
  for (std::size_t i = 0; i < 6; ++i) {
    const auto& f = scan.frames[i];
    EXPECT_LT((f.camera_to_base.translation - path[i].translation).norm(), 1e-9);
    EXPECT_EQ(f.intrinsics.width, 96);
    const core::Image depth = core::ReadPng(dir / f.depth);
    EXPECT_EQ(depth.bit_depth, 16);
    EXPECT_EQ(depth.width, 96);
    const core::Image color = core::ReadPng(dir / f.color);
    EXPECT_EQ(color.channels, 3);
    // Depth in mm: the scene is around a metre away.
    const auto* mm = reinterpret_cast<const uint16_t*>(depth.bytes.data());
    std::vector<uint16_t> returns;
    for (int p = 0; p < 96 * 72; ++p)
      if (mm[p] > 0) returns.push_back(mm[p]);
    ASSERT_GT(returns.size(), 96u * 72u / 2);
    std::nth_element(returns.begin(), returns.begin() + returns.size() / 2, returns.end());
    EXPECT_GT(returns[returns.size() / 2], 400);
    EXPECT_LT(returns[returns.size() / 2], 1600);
    for (int k = 0; k < 7; ++k) EXPECT_EQ(f.joint_positions[k], proxy.Observe(false).q[k]);
  }
  EXPECT_THROW(CaptureScan(proxy, path, ScanIntrinsics(options), dir), core::IoError)
      << "a second scan into the same directory";
}

TEST(Scan, ReadingABrokenIndexNamesTheFileAndField) {
  const auto dir = TempDir("broken");
  std::filesystem::create_directories(dir);
  { std::ofstream(dir / "frames.json") << R"({"depth_scale": 1000, "frames": [{"color": "x"}]})"; }
  try {
    core::ReadScan(dir);
    FAIL() << "read a broken index";
  } catch (const core::ConfigError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("frames.json"), std::string::npos) << what;
    EXPECT_NE(what.find("frames[0].depth"), std::string::npos) << what;
  }
  EXPECT_THROW(core::ReadScan(TempDir("missing")), core::IoError);
}

}  // namespace
}  // namespace twinforge::reality
