#include "samrl/active_camera.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <random>
#include <string>

#include "core/error.h"
#include "learn/torch_runtime.h"
#include "real2sim/calibrate/twin_geometry.h"
#include "samrl/test_scenes.h"
#include "sim/env.h"

namespace twinforge::samrl {
namespace {

using testing::Mount;
using testing::OccludedTarget;
using testing::Small;
using testing::VisibleTarget;

TEST(ActiveCamera, OrbitPoseLooksAtTheCentre) {
  const OrbitMount mount = Mount();
  for (double az : {-1.0, 0.0, 0.7})
    for (double el : {0.2, 0.9}) {
      const core::Pose pose = OrbitPose(mount, az, el);
      EXPECT_NEAR((pose.translation - mount.center).norm(), mount.radius, 1e-12);
      const Eigen::Vector3d forward = pose.rotation * Eigen::Vector3d::UnitZ();
      EXPECT_NEAR(forward.dot((mount.center - pose.translation).normalized()), 1.0, 1e-12);
      // The image's down axis points below the horizon: the picture is upright.
      EXPECT_LT((pose.rotation * Eigen::Vector3d::UnitY()).z(), 0);
      EXPECT_NEAR((pose.rotation * Eigen::Vector3d::UnitX()).z(), 0, 1e-12);
    }
}

// From a view with the target mostly behind the wall, ascent on the score through the renderer
// ends at the best view a dense grid finds (within 10%), and sampling gets near it too.
TEST(ActiveCamera, GradientAscentOnAKnownScoreFindsItsMaximum) {
  learn::PinMathThreads(1);
  const auto scene = OccludedTarget();
  const auto k = Small();
  const OrbitMount mount = Mount();
  double grid_best = 0;
  for (int i = 0; i <= 24; ++i)
    for (int j = 0; j <= 10; ++j) {
      const double az = mount.min_azimuth + (mount.max_azimuth - mount.min_azimuth) * i / 24;
      const double el = mount.min_elevation + (mount.max_elevation - mount.min_elevation) * j / 10;
      torch::NoGradGuard no_grad;
      grid_best = std::max(
          grid_best,
          VisibleTarget(real2sim::SoftRasterize(
                            scene, k, OrbitPose(mount, torch::tensor({az, el}, torch::kFloat64))))
              .item<double>());
    }
  ViewSearchOptions options;
  options.steps = 80;
  const ViewChoice ascent = AscendView(scene, k, mount, VisibleTarget, 0.15, 0.3, options);
  EXPECT_LT(ascent.scores.front(), 0.5 * grid_best) << "the start should be mostly occluded";
  EXPECT_GT(ascent.score, 0.9 * grid_best)
      << "from " << ascent.scores.front() << " to " << ascent.score << " at az " << ascent.azimuth
      << " el " << ascent.elevation << "; grid best " << grid_best;
  EXPECT_GE(ascent.azimuth, mount.min_azimuth);
  EXPECT_LE(ascent.elevation, mount.max_elevation);

  core::Rng rng(4);
  const ViewChoice sampled = SampleView(scene, k, mount, VisibleTarget, rng, options);
  EXPECT_EQ(sampled.scores.size(), 64u);
  EXPECT_GT(sampled.score, 0.8 * grid_best);
}

TEST(ActiveCamera, ABadMountIsRefused) {
  OrbitMount mount = Mount();
  mount.max_elevation = 1.6;
  EXPECT_THROW(AscendView(OccludedTarget(), Small(), mount, VisibleTarget, 0, 0.5), core::Error);
}

// What a frame showed of a box (its top and the side facing the camera) stands on the table as
// columns under the top: 3 x 3 cells of 2 cm for a 5.8 cm box, each up to the top; a few stray
// returns make no column; the columns are the same whatever order the points come in.
TEST(ActiveCamera, OccludersStandOnTheTableUnderWhatAFrameSaw) {
  std::vector<Eigen::Vector3d> points;
  for (int i = 0; i <= 58; ++i)
    for (int j = 0; j <= 58; ++j) {
      points.emplace_back(0.401 + 1e-3 * i, 0.101 + 1e-3 * j, 0.10);    // the top
      points.emplace_back(0.401, 0.101 + 1e-3 * j, 0.03 + 1.2e-3 * i);  // the near side
    }
  for (int i = 0; i < 5; ++i) points.emplace_back(0.7, -0.2 + 0.01 * i, 0.05);  // strays
  const std::vector<Occluder> columns = OccluderColumns(points, 0.02, 0.02, 20);
  ASSERT_EQ(columns.size(), 9u);
  for (const Occluder& c : columns) {
    EXPECT_NEAR(c.center.z() + 0.5 * c.size.z(), 0.10, 1e-12) << "up to the top";
    EXPECT_NEAR(c.center.z() - 0.5 * c.size.z(), 0.02, 1e-12) << "from the floor";
    EXPECT_NEAR(c.size.x(), 0.02, 1e-12);
    EXPECT_GT(c.center.x(), 0.40);
    EXPECT_LT(c.center.x(), 0.46);
    EXPECT_GT(c.center.y(), 0.10);
    EXPECT_LT(c.center.y(), 0.16);
  }
  std::shuffle(points.begin(), points.end(), std::mt19937(3));
  const std::vector<Occluder> again = OccluderColumns(points, 0.02, 0.02, 20);
  ASSERT_EQ(again.size(), columns.size());
  for (std::size_t i = 0; i < columns.size(); ++i) {
    EXPECT_EQ(again[i].center, columns[i].center);
    EXPECT_EQ(again[i].size, columns[i].size);
  }
  EXPECT_TRUE(OccluderColumns(points, 0.02, 0.2, 20).empty()) << "all under the floor";
  EXPECT_THROW(OccluderColumns(points, 0, 0.02, 20), core::Error);
}

// The active look's view is chosen around what a frame showed in the way. On the peg twin, the
// view that shows the hole block best is found; a wall the twin does not have is then put between
// the block and that view, as the columns a frame of it would give. Told of them, the look
// chooses another view, within 20% of the best a dense grid of views finds with the wall there.
TEST(ActiveCamera, AViewIsChosenAroundWhatAFrameShowedInTheWay) {
  learn::PinMathThreads(1);
  const sim::TaskSpec spec = sim::LoadTaskSpec("peg_insertion");
  const sim::Task task(spec);
  real2sim::TwinGeometry twin(spec, 600);
  sim::Env env(std::make_shared<const sim::Task>(spec));
  env.Reset(0, 0);
  std::array<double, 7> q;
  for (int i = 0; i < 7; ++i) q[i] = env.ArmPositions()[i];
  std::vector<std::pair<std::string, core::Pose>> objects;
  for (const std::string& name : spec.objects)
    objects.emplace_back(name, env.BodyPose(mj_name2id(env.model(), mjOBJ_BODY, name.c_str())));
  const OrbitMount mount = ObjectsMount(task);
  const auto k = LookSearchCamera();
  const auto choose = [&](const std::vector<Occluder>& occluders) {
    const TargetView view =
        BelievedView(twin, q, 2 * env.FingerOpening(), objects, "", {"hole_block"}, occluders);
    core::Rng rng(1);
    return std::make_pair(view, ChooseView(view.mesh, k, mount, view.score, rng, LookSearch()));
  };
  const auto [open_view, open] = choose({});

  // A wall 30 cm wide and 40 cm tall, 8 cm from the block's top toward the chosen camera.
  const Eigen::Vector3d top =
      env.SitePose(mj_name2id(env.model(), mjOBJ_SITE, "hole_top")).translation;
  const Eigen::Vector3d eye = OrbitPose(mount, open.azimuth, open.elevation).translation;
  const Eigen::Vector2d toward = (eye - top).head<2>().normalized();
  const Eigen::Vector2d across(-toward.y(), toward.x());
  std::vector<Eigen::Vector3d> wall;
  for (int i = -150; i <= 150; ++i)
    for (int j = 0; j <= 40; ++j) {
      const Eigen::Vector2d xy = top.head<2>() + 0.08 * toward + 1e-3 * i * across;
      wall.emplace_back(xy.x(), xy.y(), 0.01 * j);
    }
  const std::vector<Occluder> occluders = OccluderColumns(wall, 0.02, 0.02, 20);
  ASSERT_GT(occluders.size(), 10u);
  const auto [walled_view, around] = choose(occluders);
  const auto walled = [&](double azimuth, double elevation) {
    torch::NoGradGuard no_grad;
    return walled_view
        .score(real2sim::SoftRasterize(
            walled_view.mesh, k,
            OrbitPose(mount, torch::tensor({azimuth, elevation}, torch::kFloat64))))
        .item<double>();
  };
  const double behind = walled(open.azimuth, open.elevation);
  double grid_best = 0;
  for (int i = 0; i <= 24; ++i)
    for (int j = 0; j <= 5; ++j)
      grid_best = std::max(
          grid_best,
          walled(mount.min_azimuth + (mount.max_azimuth - mount.min_azimuth) * i / 24,
                 mount.min_elevation + (mount.max_elevation - mount.min_elevation) * j / 5));
  EXPECT_LT(behind, 0.01 * open.score) << "the wall hides the block from the first view";
  EXPECT_GT(around.score, 0.8 * grid_best)
      << "first view az " << open.azimuth << " el " << open.elevation << ": " << open.score
      << "; behind the wall " << behind << "; chosen around it az " << around.azimuth << " el "
      << around.elevation << ": " << around.score << "; the grid's best " << grid_best;
  EXPECT_GT(around.score, 0.2 * open.score);
  EXPECT_GT(std::abs(around.azimuth - open.azimuth), 0.5);
}

// peg_insertion_hidden's point: its screen, turned about the block to a new place in every scene,
// hides the hole from any one view of the camera's mount in a good share of the scenes, while in
// every scene some view sees it. Rays from a grid of the mount's views (9 azimuths x 3 elevations)
// to a point 5 mm over the hole's mouth, over 100 level-1 scenes of the twin.
TEST(ActiveCamera, NoOneViewSeesTheHiddenHoleInEveryScene) {
  auto task = std::make_shared<const sim::Task>(sim::LoadTaskSpec("peg_insertion_hidden"));
  const OrbitMount mount = ObjectsMount(*task);
  sim::Env env(task);
  const mjModel* m = env.model();
  const int site = mj_name2id(m, mjOBJ_SITE, "hole_top");
  constexpr int kAzimuths = 9, kElevations = 3, kScenes = 100;
  std::vector<int> hidden(kAzimuths * kElevations, 0);
  int seen_somewhere = 0;
  for (int scene = 0; scene < kScenes; ++scene) {
    env.Reset(scene, 1);
    const Eigen::Vector3d target =
        Eigen::Map<const Eigen::Vector3d>(env.data()->site_xpos + 3 * site) +
        Eigen::Vector3d(0, 0, 0.005);
    bool any = false;
    for (int i = 0; i < kAzimuths; ++i)
      for (int j = 0; j < kElevations; ++j) {
        const double az =
            mount.min_azimuth + (mount.max_azimuth - mount.min_azimuth) * i / (kAzimuths - 1);
        const double el = mount.min_elevation +
                          (mount.max_elevation - mount.min_elevation) * j / (kElevations - 1);
        const Eigen::Vector3d eye = env.base() * OrbitPose(mount, az, el).translation;
        const Eigen::Vector3d way = target - eye;
        int geom = -1;
        const double hit = mj_ray(m, env.data(), eye.data(), way.data(), nullptr, 1, -1, &geom);
        const bool blocked = hit >= 0 && hit < 1 - 1e-3;
        hidden[i * kElevations + j] += blocked;
        any |= !blocked;
      }
    seen_somewhere += any;
  }
  const int least = *std::min_element(hidden.begin(), hidden.end());
  EXPECT_GE(least, 20) << "a view sees the hole in all but " << least << " of " << kScenes
                       << " scenes";
  EXPECT_EQ(seen_somewhere, kScenes);
  std::string table;
  for (int j = 0; j < kElevations; ++j) {
    for (int i = 0; i < kAzimuths; ++i) table += std::to_string(hidden[i * kElevations + j]) + " ";
    table += "\n";
  }
  std::printf("scenes of %d where the hole is hidden, by view (rows: elevation up; columns: "
              "azimuth):\n%s",
              kScenes, table.c_str());
}

}  // namespace
}  // namespace twinforge::samrl
