#include "samrl/pose_estimate.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <random>
#include <sstream>
#include <string>

#include "core/fs.h"
#include "core/se3.h"
#include "core/test_support.h"
#include "samrl/pose_bench.h"
#include "sim/task.h"

namespace twinforge::samrl {
namespace {

// The square peg and the block with its square hole look the same every quarter turn; the
// spatula only once a turn. Of a fit's look-alike poses, the one nearest the twin's own is taken,
// or the one nearest where the object was believed.
TEST(PoseEstimate, LookAlikeTurnsOfSquareObjects) {
  auto peg = std::make_shared<const sim::Task>(sim::LoadTaskSpec("peg_insertion"));
  const ObjectPoseEstimator estimator(peg, {"peg", "hole_block"});
  EXPECT_EQ(estimator.symmetry(0), 4);
  EXPECT_EQ(estimator.symmetry(1), 4);
  for (int i = 0; i < 2; ++i)
    for (double turn : {0.0, 0.5, 1.0, 1.5}) {
      const double yaw = 0.2 + M_PI * turn;  // 0.2 rad from the twin's own, and quarter turns
      core::Pose fitted = estimator.nominal(i);
      fitted.translation.x() += 0.03;
      fitted.rotation = core::Yaw(yaw) * fitted.rotation;
      const core::Pose chosen = estimator.NearestLookAlike(i, fitted);
      EXPECT_NEAR(core::AngleBetween(chosen.rotation, estimator.nominal(i).rotation), 0.2, 1e-6)
          << "body " << i << ", " << turn << " half turns";
      EXPECT_TRUE(chosen.translation.isApprox(fitted.translation));
      // Seen again, nearest where it was believed: here a quarter turn from the twin's own.
      core::Pose believed = estimator.nominal(i);
      believed.rotation = core::Yaw(M_PI / 2 + 0.1) * believed.rotation;
      const core::Pose again = estimator.NearestLookAlike(i, fitted, believed);
      EXPECT_NEAR(core::AngleBetween(again.rotation, believed.rotation), 0.1, 1e-6)
          << "body " << i << ", " << turn << " half turns";
    }

  auto spatula = std::make_shared<const sim::Task>(sim::LoadTaskSpec("spatula_flipping"));
  const ObjectPoseEstimator tools(spatula, {"spatula"});
  EXPECT_EQ(tools.symmetry(0), 1);
  core::Pose reversed = tools.nominal(0);
  reversed.rotation = core::Yaw(M_PI) * reversed.rotation;
  EXPECT_NEAR(
      core::AngleBetween(tools.NearestLookAlike(0, reversed).rotation, tools.nominal(0).rotation),
      M_PI, 1e-6)
      << "a spatula turned round is not the same spatula";
}

// A disc drawn as a scan draws one: 48 rim points a ring, their radius 45 mm give or take a
// millimetre (`bumps`), and an oval dish (45 by 33 mm) drawn the same way. Its centre 3 mm off
// the body's origin, as a scanned part's frame may be.
std::string DiscMesh(const std::string& name, double rx, double ry, double bumps) {
  std::ostringstream vertices, faces;
  const int n = 48;
  for (double z : {-0.003, 0.003})
    for (int k = 0; k < n; ++k) {
      const double a = 2 * M_PI * k / n;
      const double r = 1 + bumps * (0.018 * std::sin(7 * a) + 0.009 * std::cos(3 * a + 1));
      vertices << 0.003 + rx * r * std::cos(a) << " " << ry * r * std::sin(a) << " " << z << " ";
    }
  vertices << "0.003 0 -0.003 0.003 0 0.003";
  for (int k = 0; k < n; ++k) {
    const int next = (k + 1) % n;
    faces << k << " " << next << " " << n + next << " " << k << " " << n + next << " " << n + k
          << " " << 2 * n << " " << next << " " << k << " " << 2 * n + 1 << " " << n + k << " "
          << n + next << " ";
  }
  return "<mesh name=\"" + name + "\" vertex=\"" + vertices.str() + "\" face=\"" + faces.str() +
         "\"/>";
}

// A bumpy disc on a tray, an oval dish, a box and a box with a bump on one wall.
std::shared_ptr<const sim::Task> RoundScene() {
  const auto dir = core::testing::TestDir("pose_estimate_test", "round");
  core::WriteFileAtomic(dir / "scene.xml", "<mujoco><asset>" + DiscMesh("disc", 0.045, 0.045, 1) +
                                               DiscMesh("dish", 0.045, 0.033, 1) +
                                               R"(</asset>
  <worldbody>
    <body name="tray" pos="0.5 -0.15 0.005"><geom type="box" size="0.07 0.06 0.005"/></body>
    <body name="disc" pos="0.5 -0.15 0.013" euler="0 0 0.6"><geom type="mesh" mesh="disc"/></body>
    <body name="dish" pos="0.5 0 0.003"><geom type="mesh" mesh="dish"/></body>
    <body name="box" pos="0.5 0.15 0.02"><geom type="box" size="0.02 0.02 0.02"/></body>
    <body name="bumped" pos="0.3 0.15 0.02">
      <geom type="box" size="0.02 0.02 0.02"/>
      <geom type="sphere" size="0.003" pos="0.02 0.008 0.01"/>
    </body>
  </worldbody>
</mujoco>)");
  core::WriteFileAtomic(dir / "task.yaml", R"(name: round
scene: scene.xml
success: [{type: axis_upright, body: disc, axis: [0, 0, 1], threshold: 0.9}]
randomization: {distractors: {max_count: 0, count: [0, 0]}}
camera: {position: [1.2, 0.3, 0.6], look_at: [0.55, 0.0, 0.1], fovy_deg: 45, width: 80, height: 60}
)");
  return std::make_shared<const sim::Task>(sim::LoadTaskSpec((dir / "task.yaml").string()));
}

// A round object's turn cannot be seen, so a fit's turn is arbitrary and the sites round it (a
// pancake's near edge, where the blade goes under) would swing with it: the twin's own turn is
// taken, about the object's own axis, and on what it stands on, as that was found turned. A scanned
// disc is round to a few millimetres, not to the 1 mm a square's quarter turns are held to; an oval
// dish is not round, nor a square box.
TEST(PoseEstimate, ARoundObjectTakesTheTurnItIsBelievedAt) {
  const auto task = RoundScene();
  const ObjectPoseEstimator estimator(task, {"disc", "dish", "box", "tray"});
  EXPECT_EQ(estimator.symmetry(0), 0) << "the bumpy disc is round";
  EXPECT_EQ(estimator.symmetry(1), 1) << "an oval dish is not";
  EXPECT_EQ(estimator.symmetry(2), 4);
  EXPECT_EQ(estimator.symmetry(3), 2);

  // Fitted 1.3 rad round from the twin's own, 2 cm along: the twin's turn, about the disc's own
  // centre, which stays where the fit put it.
  const core::Pose nominal = estimator.nominal(0);
  core::Pose fitted = nominal;
  fitted.translation.x() += 0.02;
  fitted.rotation = core::Yaw(1.3) * fitted.rotation;
  const Eigen::Vector3d centre(0.003, 0, 0);  // body frame
  const core::Pose chosen = estimator.NearestLookAlike(0, fitted);
  EXPECT_NEAR(core::AngleBetween(chosen.rotation, nominal.rotation), 0, 1e-9);
  EXPECT_LT((chosen * centre - fitted * centre).norm(), 1e-3);
  EXPECT_GT((chosen.translation - fitted.translation).norm(), 1e-3)
      << "turned about its centre, not its origin";
  // On its tray, found 0.3 rad round and 1 cm along: the disc's reference turns with the tray;
  // what stands on nothing keeps the twin's own.
  std::vector<core::Pose> found;
  for (int i = 0; i < 4; ++i) found.push_back(estimator.nominal(i));
  found[3].rotation = core::Yaw(0.3) * found[3].rotation;
  found[3].translation.y() += 0.01;
  const core::Pose on_tray = estimator.NominalOn(0, found);
  EXPECT_NEAR(core::AngleBetween(on_tray.rotation, nominal.rotation), 0.3, 1e-9);
  EXPECT_LT(
      (on_tray.translation - found[3] * (estimator.nominal(3).Inverse() * nominal.translation))
          .norm(),
      1e-9);
  EXPECT_NEAR(core::AngleBetween(estimator.NominalOn(0, found).rotation,
                                 estimator.NearestLookAlike(0, fitted, on_tray).rotation),
              0, 1e-9);
  EXPECT_TRUE(estimator.NominalOn(2, found).translation.isApprox(estimator.nominal(2).translation));
  EXPECT_TRUE(estimator.NominalOn(3, found).translation.isApprox(estimator.nominal(3).translation))
      << "the tray stands on nothing estimated";
  // Seen again, the turn it was believed at.
  core::Pose believed = nominal;
  believed.rotation = core::Yaw(-0.4) * believed.rotation;
  EXPECT_NEAR(core::AngleBetween(estimator.NearestLookAlike(0, fitted, believed).rotation,
                                 believed.rotation),
              0, 1e-9);
}

// Points on a surface (body frame) `apart` m apart over the box [lo, hi], keeping those `keep`
// says.
std::vector<Eigen::Vector3d> Grid(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi,
                                  double apart,
                                  const std::function<bool(const Eigen::Vector3d&)>& keep) {
  std::vector<Eigen::Vector3d> out;
  for (double x = lo.x(); x <= hi.x() + 1e-9; x += apart)
    for (double y = lo.y(); y <= hi.y() + 1e-9; y += apart)
      for (double z = lo.z(); z <= hi.z() + 1e-9; z += apart)
        if (keep({x, y, z})) out.emplace_back(x, y, z);
  return out;
}

// A round body's starts are at one yaw per cell: any turn of it is the same surface. The bumpy
// disc is found where it was moved to from them, as the box (turned 0.3 rad) from its eight.
TEST(PoseEstimate, ARoundBodyIsStartedAtOneYaw) {
  const auto task = RoundScene();
  const Eigen::Vector3d centre(0.003, 0, 0);  // the disc's, body frame
  // Its top and rim, 3 mm apart; the box's top and sides.
  const auto disc = Grid({-0.045, -0.048, -0.003}, {0.051, 0.048, 0.003}, 0.003, [&](auto p) {
    const double r = (p.template head<2>() - centre.head<2>()).norm();
    return (p.z() > 0.0029 && r < 0.044) || (r > 0.0435 && r < 0.0465);
  });
  const auto box = Grid({-0.02, -0.02, -0.02}, {0.02, 0.02, 0.02}, 0.004, [](auto p) {
    return p.z() > 0.0199 || p.cwiseAbs().template head<2>().maxCoeff() > 0.0199;
  });
  const auto fits = [&](int yaw_starts) {
    PoseEstimateOptions options;
    options.yaw_starts = yaw_starts;
    const ObjectPoseEstimator estimator(task, {"disc", "box"}, options);
    core::Pose disc_at = estimator.nominal(0), box_at = estimator.nominal(1);
    disc_at.translation += Eigen::Vector3d(0.015, -0.01, 0);
    box_at.translation += Eigen::Vector3d(-0.01, 0.012, 0);
    box_at.rotation = core::Yaw(0.3) * box_at.rotation;
    std::vector<Eigen::Vector3d> points;
    for (const auto& p : disc) points.push_back(disc_at * p);
    for (const auto& p : box) points.push_back(box_at * p);
    const std::vector<ObjectPose> fit = estimator.Estimate(points);
    EXPECT_TRUE(fit[0].seen && fit[1].seen);
    EXPECT_LT((fit[0].pose * centre - disc_at * centre).head<2>().norm(), 0.0015);
    const core::Pose box_fit = estimator.NearestLookAlike(1, fit[1].pose, box_at);
    EXPECT_LT((box_fit.translation - box_at.translation).head<2>().norm(), 0.0015);
    EXPECT_LT(core::AngleBetween(box_fit.rotation, box_at.rotation), 0.02);
    return std::pair{fit[0].starts, fit[1].starts};
  };
  const auto [disc_8, box_8] = fits(8);
  const auto [disc_1, box_1] = fits(1);
  EXPECT_GT(disc_1, 0);
  EXPECT_EQ(disc_8, disc_1) << "a round body, one yaw per cell";
  EXPECT_EQ(box_8, 8 * box_1) << "a square box, each of its eight";
}

// Straight over the peg's block, a camera that sees the table under its walls sees through where
// the block would stand; not its top, the table down its hole or beside it. The table beside it is
// seen through the block moved there.
TEST(PoseEstimate, CountsThePointsSeenThroughWhereAnObjectWouldStand) {
  auto peg = std::make_shared<const sim::Task>(sim::LoadTaskSpec("peg_insertion"));
  const ObjectPoseEstimator estimator(peg, {"peg", "hole_block"});
  const core::Pose block = estimator.nominal(1);
  const Eigen::Vector3d camera = block * Eigen::Vector3d(0, 0, 0.5);
  // In the block's frame (its origin at its middle, 2 cm up): the table under each of its four
  // walls, each wall's top, the table down the hole, and the table 6 cm off its side.
  const double table = -0.02;
  std::vector<Eigen::Vector3d> under, top;
  for (const Eigen::Vector2d w : {Eigen::Vector2d(0.0215, 0), Eigen::Vector2d(-0.0215, 0),
                                  Eigen::Vector2d(0, 0.0215), Eigen::Vector2d(0, -0.0215)}) {
    under.push_back(block * Eigen::Vector3d(w.x(), w.y(), table));
    top.push_back(block * Eigen::Vector3d(w.x(), w.y(), 0.02));
  }
  const std::vector<Eigen::Vector3d> hole{block * Eigen::Vector3d(0, 0, table)};
  const std::vector<Eigen::Vector3d> beside{block * Eigen::Vector3d(0.0915, 0, table)};
  const double margin = 0.01;
  EXPECT_EQ(estimator.SeenThrough(1, block, camera, under, margin), 4);
  EXPECT_EQ(estimator.SeenThrough(1, block, camera, top, margin), 0);
  EXPECT_EQ(estimator.SeenThrough(1, block, camera, hole, margin), 0);
  EXPECT_EQ(estimator.SeenThrough(1, block, camera, beside, margin), 0);
  core::Pose moved = block;
  moved.translation.x() += 0.07;
  EXPECT_EQ(estimator.SeenThrough(1, moved, camera, beside, margin), 1);
  EXPECT_EQ(estimator.SeenThrough(1, moved, camera, top, margin), 0)
      << "short of where it would be";
  const Eigen::Vector3d from_afar = moved * Eigen::Vector3d(0, 0, 0.5);
  core::Pose away = moved;
  away.translation.y() += 0.2;
  EXPECT_EQ(estimator.SeenThrough(1, away, from_afar, under, margin), 0) << "the rays pass by";
  // Within the margin of its surface a point is not seen through it.
  EXPECT_EQ(
      estimator.SeenThrough(1, block, camera,
                            {block * Eigen::Vector3d(0.0215, 0, 0.02 - 0.5 * margin)}, margin),
      0);
}

// The drawn griddle turned 15 deg and moved 1.3 cm, as a camera over it sees it: points 4 mm
// apart on its top and its lip's, 12 mm on its near side, one end and the lip's side, each off by
// up to 2 mm. The starts' fit, point to point, is held back by the top's points, each paired with
// the top straight under it: it is found turned 8.0 deg (a scanned griddle on the proxy, 3.6 deg
// for 15; the fit until stop 88). Polished point to plane, it is found turned 15.0 deg, and where
// it stands to 0.2 mm.
TEST(PoseEstimate, AFlatTopDoesNotHoldBackTheTurn) {
  auto spatula = std::make_shared<const sim::Task>(sim::LoadTaskSpec("spatula_flipping"));
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> noise(-0.002, 0.002);
  std::vector<Eigen::Vector3d> local;  // body frame: the box 18 x 22 x 2.5 cm, the lip over it
  const auto face = [&](const Eigen::Vector3d& corner, const Eigen::Vector3d& u,
                        const Eigen::Vector3d& v, double apart) {
    const int nu = std::max(1, int(u.norm() / apart)), nv = std::max(1, int(v.norm() / apart));
    for (int i = 0; i <= nu; ++i)
      for (int j = 0; j <= nv; ++j) {
        const Eigen::Vector3d p = corner + u * i / nu + v * j / nv;
        if (p.z() > 0.0249 && p.z() < 0.0251 && std::abs(p.x() + 0.025) < 0.006 &&
            std::abs(p.y()) < 0.081)
          continue;  // under the lip
        local.push_back(p + Eigen::Vector3d(noise(rng), noise(rng), noise(rng)));
      }
  };
  face({-0.09, -0.11, 0.025}, {0.18, 0, 0}, {0, 0.22, 0}, 0.004);  // top
  face({-0.09, -0.11, 0}, {0, 0.22, 0}, {0, 0, 0.025}, 0.012);     // near side
  face({-0.09, -0.11, 0}, {0.18, 0, 0}, {0, 0, 0.025}, 0.012);     // one end
  face({-0.03, -0.08, 0.035}, {0.01, 0, 0}, {0, 0.16, 0}, 0.004);  // the lip's top
  face({-0.03, -0.08, 0.025}, {0, 0.16, 0}, {0, 0, 0.01}, 0.012);  // its near side
  PoseEstimateOptions options;
  const auto found = [&](bool polish, int start_points = PoseEstimateOptions{}.start_points,
                         int yaw_starts = PoseEstimateOptions{}.yaw_starts) {
    options.polish = polish;
    options.start_points = start_points;
    options.yaw_starts = yaw_starts;
    const ObjectPoseEstimator estimator(spatula, {"griddle"}, options);
    core::Pose moved = estimator.nominal(0);
    moved.rotation = core::Yaw(15 * M_PI / 180) * moved.rotation;
    moved.translation += Eigen::Vector3d(0.01, -0.008, 0);
    std::vector<Eigen::Vector3d> points;
    for (const auto& p : local) points.push_back(moved * p);
    const ObjectPose fit = estimator.Estimate(points)[0];
    EXPECT_TRUE(fit.seen);
    return std::pair{
        core::ToRollPitchYaw((fit.pose * estimator.nominal(0).Inverse()).rotation).z() * 180 / M_PI,
        (fit.pose.translation - moved.translation).head<2>().norm()};
  };
  const auto [turn, off] = found(true);
  EXPECT_NEAR(turn, 15, 1);
  EXPECT_LT(off, 0.003);
  // The starts stepped on 500 of the points near them (of about 2700); on all of them, the same
  // (two yaws a cell, not eight: all the points take five times as long).
  const auto [few_turn, few_off] = found(true, PoseEstimateOptions{}.start_points, 2);
  const auto [every_turn, every_off] = found(true, 0, 2);
  EXPECT_NEAR(few_turn, every_turn, 0.2);
  EXPECT_NEAR(few_off, every_off, 0.0005);
  EXPECT_NEAR(few_turn, 15, 1);
  EXPECT_LT(found(false).first, 10) << "not polished, as until stop 88";
}

// Seen again, an object is fitted with where it was believed as a reference: the quarter turn of
// the fit nearest it, polished and settled, is taken if it scores within the margin. The drawn
// mug is not the same turned (its handle): seen from the handle's side, its own turn is kept
// against a belief a quarter turn off.
TEST(PoseEstimate, ALookAlikeTurnNearTheBeliefIsKeptOnlyWhenTheFrameCannotTellThemApart) {
  auto mugs = std::make_shared<const sim::Task>(sim::LoadTaskSpec("mug_on_shelf"));
  const ObjectPoseEstimator estimator(mugs, {"mug"});
  ASSERT_EQ(estimator.symmetry(0), 1);
  // Body frame: the cup's side (radius 40 mm, 86 mm tall) and top, 3 mm apart; the handle's
  // outer bar (x 60-80 mm) and its two arms on +x.
  const auto cup_side = [](double from, double to) {
    std::vector<Eigen::Vector3d> out;
    for (double a = from; a <= to + 1e-9; a += 0.075)
      for (double z = -0.04; z <= 0.044; z += 0.003)
        out.emplace_back(0.04 * std::cos(a), 0.04 * std::sin(a), z);
    return out;
  };
  const auto top = Grid({-0.04, -0.04, 0.045}, {0.04, 0.04, 0.045}, 0.003,
                        [](auto p) { return p.template head<2>().norm() < 0.0395; });
  const auto handle = Grid({0.04, -0.006, -0.029}, {0.08, 0.006, 0.029}, 0.003, [](auto p) {
    const bool bar = p.x() >= 0.06 && (p.x() > 0.0795 || std::abs(p.y()) > 0.0059);
    const bool arms = p.x() < 0.061 && std::abs(std::abs(p.z()) - 0.024) <= 0.005 &&
                      (std::abs(p.y()) > 0.0059 || std::abs(std::abs(p.z()) - 0.024) > 0.0049);
    return bar || arms;
  });
  core::Pose at = estimator.nominal(0);
  at.translation += Eigen::Vector3d(0.012, -0.008, 0);
  at.rotation = core::Yaw(0.2) * at.rotation;
  core::Pose believed = at;
  believed.rotation = core::Yaw(M_PI / 2) * at.rotation;
  const auto fit = [&](const std::vector<std::vector<Eigen::Vector3d>>& parts) {
    std::vector<Eigen::Vector3d> points;
    for (const auto& part : parts)
      for (const auto& p : part) points.push_back(at * p);
    const ObjectPose found = estimator.Estimate(points, {}, {believed})[0];
    EXPECT_TRUE(found.seen);
    return found.pose;
  };
  const core::Pose handle_seen = fit({cup_side(-M_PI / 2, M_PI / 2), top, handle});
  EXPECT_LT(core::AngleBetween(handle_seen.rotation, at.rotation), 0.05)
      << "the handle is seen: the mug's own turn";
  EXPECT_LT((handle_seen.translation - at.translation).head<2>().norm(), 0.002);

  // A box with a bump on its +x wall (a scanned block's lump) is not the same turned, but with its
  // top and -x wall seen a quarter turn of it explains them as well: the one believed is kept.
  const auto task = RoundScene();
  const ObjectPoseEstimator boxes(task, {"bumped"});
  ASSERT_EQ(boxes.symmetry(0), 1);
  PoseEstimateOptions no_margin;
  no_margin.turn_margin = 0;
  const ObjectPoseEstimator own_turn(task, {"bumped"}, no_margin);
  const auto seen = Grid({-0.02, -0.02, -0.02}, {0.02, 0.02, 0.02}, 0.004,
                         [](auto p) { return p.z() > 0.0199 || p.x() < -0.0199; });
  core::Pose box_at = boxes.nominal(0);
  box_at.translation += Eigen::Vector3d(-0.01, 0.006, 0);
  box_at.rotation = core::Yaw(0.15) * box_at.rotation;
  std::vector<Eigen::Vector3d> points;
  for (const auto& p : seen) points.push_back(box_at * p);
  for (const double quarter : {1.0, -1.0}) {
    core::Pose box_believed = box_at;
    box_believed.rotation = core::Yaw(quarter * M_PI / 2 + 0.05) * box_at.rotation;
    const ObjectPose found = boxes.Estimate(points, {}, {box_believed})[0];
    EXPECT_TRUE(found.seen);
    EXPECT_LT(core::AngleBetween(found.pose.rotation, box_believed.rotation), 0.1)
        << quarter << " quarter turn: the believed turn";
    EXPECT_LT((found.pose * Eigen::Vector3d(0, 0, 0.02) - box_at * Eigen::Vector3d(0, 0, 0.02))
                  .head<2>()
                  .norm(),
              0.002)
        << "where it stands";
    // With no belief, or no margin, the fit's own turn.
    EXPECT_GT(core::AngleBetween(boxes.Estimate(points)[0].pose.rotation, box_believed.rotation),
              1.0);
    EXPECT_GT(core::AngleBetween(own_turn.Estimate(points, {}, {box_believed})[0].pose.rotation,
                                 box_believed.rotation),
              1.0);
  }
}

// `sim bench --pose`: the estimate on a frame of the peg twin, timed against raw closest-point
// passes over the same points, both objects found where the reset put them.
TEST(PoseBench, TimesTheEstimateAgainstRawQueriesAndReportsItsErrors) {
  auto peg = std::make_shared<const sim::Task>(sim::LoadTaskSpec("peg_insertion"));
  PoseBenchOptions options;
  options.repeats = 1;
  options.capture_scale = 4;
  const nlohmann::json out = RunPoseBench(peg, options);
  EXPECT_GT(out.at("foreground_points").get<int>(), 200);
  EXPECT_GT(out.at("raw_closest_points_per_s").get<double>(), 0);
  EXPECT_GT(out.at("estimate_in_raw_passes").get<double>(), 1) << "a fit is many passes";
  EXPECT_GT(out.at("estimate_seconds_every_point").get<double>(), 0);
  for (const char* body : {"peg", "hole_block"})
    for (const char* errors : {"errors", "errors_every_point"}) {
      const auto& e = out.at(errors).at(body);
      EXPECT_TRUE(e.at("seen").get<bool>()) << body;
      EXPECT_GT(e.at("starts").get<int>(), 0) << body;
      EXPECT_LT(e.at("mm").get<double>(), 3) << body;
      EXPECT_LT(e.at("deg").get<double>(), 3) << body;
    }
}

}  // namespace
}  // namespace twinforge::samrl
