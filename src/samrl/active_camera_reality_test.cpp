#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "learn/torch_runtime.h"
#include "reality/proxy_reality.h"
#include "samrl/active_camera.h"
#include "sim/camera.h"

namespace twinforge::samrl {
namespace {

// Where the hidden world's hole lands in a real frame: the nearest depth measured within two
// pixels of it (the dark block drops many returns), against the hole's own depth (m). A
// grader's view: only the test reads the hidden world.
std::pair<double, double> DepthAtTheHole(const reality::ProxyReality& proxy,
                                         const reality::RgbdFrame& frame) {
  const sim::Env& hidden = proxy.hidden_env();
  const int site = mj_name2id(hidden.model(), mjOBJ_SITE, "hole_top");
  const Eigen::Vector3d p = frame.extrinsics.Inverse() * hidden.SitePose(site).translation;
  const auto& k = frame.intrinsics;
  const int u = int(std::lround(k.fx * p.x() / p.z() + k.cx));
  const int v = int(std::lround(k.fy * p.y() / p.z() + k.cy));
  EXPECT_TRUE(u >= 0 && u < k.width && v >= 0 && v < k.height) << u << "," << v;
  double nearest = INFINITY;
  for (int dv = -2; dv <= 2; ++dv)
    for (int du = -2; du <= 2; ++du) {
      const int uu = std::clamp(u + du, 0, k.width - 1), vv = std::clamp(v + dv, 0, k.height - 1);
      const uint16_t mm = frame.depth[vv * k.width + uu];
      if (mm > 0) nearest = std::min(nearest, mm * 1e-3);
    }
  return {nearest, p.z()};
}

// SAM-RL's active camera on the occluded peg: the view is chosen in the twin (the hole block
// must fill as much of it as it can), and the proxy's camera, moved there, sees the hole that
// the task's fixed camera sees only the panel in front of.
TEST(ActiveCameraOnReality, AViewChosenInTheTwinSeesTheHoleTheFixedCameraCannot) {
  learn::PinMathThreads(1);
  const sim::TaskSpec task = sim::LoadTaskSpec("peg_insertion_occluded");
  reality::ProxyReality proxy(reality::ResolveWorldDir("peg_insertion_occluded"));
  const reality::Observation o = proxy.Reset({5, 0});
  std::array<double, 7> q;
  for (int i = 0; i < 7; ++i) q[i] = o.q[i];

  real2sim::TwinGeometry twin(task, 600);
  const TargetView view = TargetVisibility(twin, q, o.gripper_width, {"hole_block"});
  sim::Env env(std::make_shared<const sim::Task>(task));
  env.Reset(0, 0);
  OrbitMount mount;
  mount.center = env.SitePose(mj_name2id(env.model(), mjOBJ_SITE, "hole_top")).translation;
  mount.radius = 0.6;
  mount.min_azimuth = -2.5;
  mount.max_azimuth = 2.5;
  mount.min_elevation = 0.3;
  mount.max_elevation = 1.3;
  core::PinholeIntrinsics k{40, 30, 36, 36, 19.5, 14.5};
  ViewSearchOptions options;
  options.samples = 24;
  options.steps = 30;
  core::Rng rng(2);
  const ViewChoice choice = ChooseView(view.mesh, k, mount, view.score, rng, options);

  // In the twin: the fixed camera shows next to none of the block, the chosen view a lot.
  const sim::Camera fixed = sim::MakeCamera(task.camera);
  const double fixed_score =
      view.score(real2sim::SoftRasterize(view.mesh, k, real2sim::ToTensor(fixed.pose)))
          .item<double>();
  EXPECT_GT(choice.score, 5 * std::max(fixed_score, 0.05))
      << "fixed " << fixed_score << ", chosen " << choice.score;

  // On reality: the fixed camera's frame sees the panel where the hole is; a frame captured
  // from the chosen pose sees the hole.
  const auto [fixed_depth, fixed_hole] = DepthAtTheHole(proxy, o.frames.front());
  EXPECT_LT(fixed_depth, fixed_hole - 0.1);
  const reality::RgbdFrame moved = proxy.Capture(
      {OrbitPose(mount, choice.azimuth, choice.elevation), {80, 60, 72, 72, 39.5, 29.5}});
  const auto [moved_depth, moved_hole] = DepthAtTheHole(proxy, moved);
  EXPECT_TRUE(std::isfinite(moved_depth)) << "no depth return near the hole";
  EXPECT_GT(moved_depth, moved_hole - 0.03)
      << "something stands in front of the hole: " << moved_depth << " m against " << moved_hole
      << " m; chosen az " << choice.azimuth << " el " << choice.elevation;
}

}  // namespace
}  // namespace twinforge::samrl
