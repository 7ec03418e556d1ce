// A scan taken through the robot interface is read by Open3D's own readers and fuses into a
// surface that lies on the (hidden) scene: the layout, units and pose conventions are right.
#include <gtest/gtest.h>
#include <open3d/Open3D.h>

#include "core/test_support.h"
#include "real2sim/mesh.h"
#include "reality/proxy_reality.h"
#include "reality/scan.h"
#include "sim/camera.h"

namespace twinforge::real2sim {
namespace {

TEST(ScanLayout, Open3dReadsAndFusesIt) {
  reality::ProxyReality proxy(reality::ResolveWorldDir("open_drawer"));
  proxy.Reset({4, 1});
  reality::ScanOptions options;
  options.width = 320;
  options.height = 240;
  options.frames_per_ring = 6;
  const auto dir = core::testing::TestDir("scan_open3d");
  const auto path = reality::ScanPath(sim::LoadTaskSpec("open_drawer"), options);
  reality::CaptureScan(proxy, path, reality::ScanIntrinsics(options), dir);

  open3d::camera::PinholeCameraTrajectory trajectory;
  ASSERT_TRUE(
      open3d::io::ReadPinholeCameraTrajectory((dir / "trajectory.json").string(), trajectory));
  ASSERT_EQ(trajectory.parameters_.size(), path.size());
  open3d::camera::PinholeCameraIntrinsic intrinsic;
  ASSERT_TRUE(open3d::io::ReadIJsonConvertible((dir / "intrinsic.json").string(), intrinsic));
  EXPECT_EQ(intrinsic.width_, 320);

  open3d::pipelines::integration::ScalableTSDFVolume volume(
      0.004, 0.02, open3d::pipelines::integration::TSDFVolumeColorType::RGB8);
  char name[32];
  for (std::size_t i = 0; i < path.size(); ++i) {
    std::snprintf(name, sizeof name, "%06zu.png", i);
    auto color = open3d::io::CreateImageFromFile((dir / "color" / name).string());
    auto depth = open3d::io::CreateImageFromFile((dir / "depth" / name).string());
    ASSERT_EQ(depth->bytes_per_channel_, 2);
    auto rgbd =
        open3d::geometry::RGBDImage::CreateFromColorAndDepth(*color, *depth, 1000.0, 2.0, false);
    volume.Integrate(*rgbd, trajectory.parameters_[i].intrinsic_,
                     trajectory.parameters_[i].extrinsic_);
  }
  const auto fused = volume.ExtractPointCloud();
  ASSERT_GT(fused->points_.size(), 5000u);

  // Distances from fused points (above the floor) to the hidden scene's visible surfaces.
  const mjModel* m = proxy.hidden_env().model();
  const sim::SurfaceSampler sampler(m, (1u << 0) | (1u << 1) | (1u << 2), 400000, 64, 60000);
  std::vector<float> samples(3 * sampler.capacity());
  const sim::Workspace everywhere{Eigen::Vector3f::Constant(-10), Eigen::Vector3f::Constant(10)};
  const int n = sampler.Transform(m, proxy.hidden_env().data(), proxy.hidden_env().base(),
                                  everywhere, samples.data());
  std::vector<Eigen::Vector3d> truth, above_floor;
  for (int i = 0; i < n; ++i)
    truth.emplace_back(samples[3 * i], samples[3 * i + 1], samples[3 * i + 2]);
  for (const auto& p : fused->points_)
    if (p.z() >= 0.01) above_floor.push_back(p);  // the floor plane is not sampled
  std::vector<double> distances = NearestDistances(above_floor, truth);
  ASSERT_GT(distances.size(), 2000u);
  std::sort(distances.begin(), distances.end());
  const double median = distances[distances.size() / 2];
  const double p90 = distances[distances.size() * 9 / 10];
  std::printf("fused %zu points: median %.1f mm, 90th percentile %.1f mm from the scene\n",
              distances.size(), 1e3 * median, 1e3 * p90);
  EXPECT_LT(median, 0.004);
  EXPECT_LT(p90, 0.012);
}

}  // namespace
}  // namespace twinforge::real2sim
