#include "real2sim/calibrate/mesh_refine.h"

#include <gtest/gtest.h>
#include <open3d/Open3D.h>

#include <cmath>

#include "core/error.h"

namespace twinforge::real2sim {
namespace {

const Eigen::Vector3d kCentre(0.5, 0.0, 0.1);
constexpr double kRadius = 0.05;

// A latitude-longitude sphere about kCentre whose radius in direction d is radius(d), coloured
// by colour(d).
template <class Radius, class Colour>
Mesh Sphere(Radius radius, Colour colour, int rings = 20, int segments = 40) {
  Mesh mesh;
  auto add = [&](const Eigen::Vector3d& d) {
    mesh.vertices.push_back(kCentre + radius(d) * d);
    mesh.colors.push_back(colour(d));
    return static_cast<int>(mesh.vertices.size()) - 1;
  };
  const int top = add(Eigen::Vector3d::UnitZ());
  for (int i = 1; i < rings; ++i) {
    const double theta = M_PI * i / rings;
    for (int j = 0; j < segments; ++j) {
      const double phi = 2 * M_PI * j / segments;
      add({std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi), std::cos(theta)});
    }
  }
  const int bottom = add(-Eigen::Vector3d::UnitZ());
  auto at = [&](int ring, int j) { return 1 + (ring - 1) * segments + (j % segments); };
  for (int j = 0; j < segments; ++j) {
    mesh.triangles.emplace_back(top, at(1, j), at(1, j + 1));
    for (int i = 1; i + 1 < rings; ++i) {
      mesh.triangles.emplace_back(at(i, j), at(i + 1, j), at(i + 1, j + 1));
      mesh.triangles.emplace_back(at(i, j), at(i + 1, j + 1), at(i, j + 1));
    }
    mesh.triangles.emplace_back(at(rings - 1, j), bottom, at(rings - 1, j + 1));
  }
  return mesh;
}

Eigen::Vector3d TrueColour(const Eigen::Vector3d& d) {
  return {0.5 + 0.3 * d.x(), 0.4 + 0.2 * d.y(), 0.6 - 0.3 * d.z()};
}

// A camera at `eye` looking at the sphere's centre (OpenCV axes: z forward, y down).
core::Pose LookAt(const Eigen::Vector3d& eye) {
  const Eigen::Vector3d z = (kCentre - eye).normalized();
  const Eigen::Vector3d x = z.cross(Eigen::Vector3d::UnitZ()).normalized();
  const Eigen::Vector3d y = z.cross(x);
  Eigen::Matrix3d r;
  r << x, y, z;
  return {eye, core::Quat(r)};
}

// What a camera at `eye` sees of `truth` standing on a table (the table is fixed: it is not
// refined, but hides and is seen).
RefineView View(const Mesh& truth, const Eigen::Vector3d& eye) {
  torch::NoGradGuard no_grad;
  RefineView view;
  view.intrinsics = {128, 96, 110, 110, 63.5, 47.5};
  view.camera_to_base = LookAt(eye);
  view.fixed = BoxMesh({0.5, 0, 0.04}, {0.6, 0.6, 0.02}, {0.7, 0.7, 0.6});
  std::vector<double> v, c;
  for (size_t i = 0; i < truth.vertices.size(); ++i)
    for (int k = 0; k < 3; ++k) {
      v.push_back(truth.vertices[i][k]);
      c.push_back(truth.colors[i][k]);
    }
  std::vector<int64_t> f;
  for (const auto& t : truth.triangles) f.insert(f.end(), {t[0], t[1], t[2]});
  const auto dbl = torch::TensorOptions().dtype(torch::kFloat64);
  const int64_t n = static_cast<int64_t>(truth.vertices.size());
  RasterMesh mesh{torch::from_blob(v.data(), {n, 3}, dbl).clone(),
                  torch::from_blob(f.data(), {static_cast<int64_t>(f.size() / 3), 3},
                                   torch::TensorOptions().dtype(torch::kInt64))
                      .clone(),
                  torch::from_blob(c.data(), {n, 3}, dbl).clone()};
  SoftRasterOptions sharp;
  sharp.sigma = 0.05;
  const SoftImage image = SoftRasterize(JoinMeshes({mesh, view.fixed}), view.intrinsics,
                                        ToTensor(view.camera_to_base), sharp);
  view.depth = image.depth * (image.silhouette > 0.5).to(torch::kFloat64);
  view.rgb = image.rgb;
  return view;
}

// Six views of `truth` whose reported poses are off by up to 2.4 mm and 4 mrad about their
// centres, as a hand camera's are, by errors that average to zero over the views (base frame).
// `truths` gets the true poses.
std::vector<RefineView> HandCameraViews(const Mesh& truth, std::vector<core::Pose>* truths) {
  std::vector<RefineView> views;
  const double size[] = {1, -1, 0.5, -0.5, 0.8, -0.8};
  int n = 0;
  for (const auto& eye : {Eigen::Vector3d(0.15, 0.1, 0.35), Eigen::Vector3d(0.2, -0.2, 0.3),
                          Eigen::Vector3d(0.2, 0.25, 0.25), Eigen::Vector3d(0.3, 0.0, 0.5),
                          Eigen::Vector3d(0.5, 0.35, 0.3), Eigen::Vector3d(0.5, -0.35, 0.3)}) {
    views.push_back(View(truth, eye));
    truths->push_back(views.back().camera_to_base);
    const double s = size[n++];
    core::Pose& pose = views.back().camera_to_base;
    pose.translation += s * Eigen::Vector3d(0.0015, -0.001, 0.0015);
    pose.rotation =
        core::Quat(Eigen::AngleAxisd(0.004 * s, Eigen::Vector3d(1, -0.5, 0.5).normalized())) *
        pose.rotation;
  }
  return views;
}

TEST(MeshRefine, ABumpInTheScanIsPressedBackAndItsColoursCorrected) {
  const Mesh truth = Sphere([](const Eigen::Vector3d&) { return kRadius; }, TrueColour);
  // The scan: a 6 mm bump facing the cameras, and colours washed out by 0.15.
  const Eigen::Vector3d bump_at = Eigen::Vector3d(-1, 0.3, 0.4).normalized();
  auto bumped = [&](const Eigen::Vector3d& d) {
    const double angle = std::acos(std::clamp(d.dot(bump_at), -1.0, 1.0));
    return kRadius + 0.006 * std::exp(-angle * angle / (2 * 0.4 * 0.4));
  };
  const Mesh scan = Sphere(bumped, [](const Eigen::Vector3d& d) {
    return (TrueColour(d) + Eigen::Vector3d::Constant(0.15)).cwiseMin(1.0).eval();
  });
  std::vector<core::Pose> truths;
  const std::vector<RefineView> views = HandCameraViews(truth, &truths);
  // How far the views' poses are from the truth: mm at the sphere (0.4 m away).
  auto pose_error = [&](const std::vector<core::Pose>& poses) {
    double e = 0;
    for (size_t i = 0; i < poses.size(); ++i) {
      const core::Pose d = truths[i].Inverse() * poses[i];
      e += 1000 * (d.translation.norm() + 0.4 * Eigen::AngleAxisd(d.rotation).angle());
    }
    return e / poses.size();
  };

  // Radial error of each vertex on the half the cameras see (x < centre), mm; colour error.
  auto errors = [&](const Mesh& m) {
    double radial = 0, colour = 0;
    int n = 0;
    for (size_t i = 0; i < m.vertices.size(); ++i) {
      const Eigen::Vector3d d = m.vertices[i] - kCentre;
      if (d.x() > -0.01 || d.z() < -0.02) continue;
      radial += 1000 * std::abs(d.norm() - kRadius);
      colour += (m.colors[i] - TrueColour(d.normalized())).cwiseAbs().mean();
      ++n;
    }
    return std::make_pair(radial / n, colour / n);
  };
  MeshRefineOptions options;
  const MeshRefinement refined = RefineMeshes({scan}, views, options);
  ASSERT_EQ(refined.meshes.size(), 1u);
  const auto [radial_before, colour_before] = errors(scan);
  const auto [radial_after, colour_after] = errors(refined.meshes[0]);
  std::printf("radial error %.2f -> %.2f mm, colour %.3f -> %.3f; depth %.2f -> %.2f mm\n",
              radial_before, radial_after, colour_before, colour_after, refined.depth_error_before,
              refined.depth_error_after);
  EXPECT_GT(radial_before, 1.2);
  EXPECT_LT(radial_after, 0.25 * radial_before);
  EXPECT_LT(colour_after, 0.1 * colour_before);
  EXPECT_LT(refined.depth_error_after, 0.5 * refined.depth_error_before);
  EXPECT_LE(refined.offset_max, options.max_offset + 1e-9);
  std::vector<core::Pose> reported, corrected;
  for (size_t i = 0; i < views.size(); ++i) {
    reported.push_back(views[i].camera_to_base);
    corrected.push_back(views[i].camera_to_base * refined.frame_corrections[i]);
  }
  std::printf("view pose error %.2f -> %.2f mm\n", pose_error(reported), pose_error(corrected));
  EXPECT_LT(pose_error(corrected), 0.4 * pose_error(reported));
}

// The twin's table 2 mm below the one the frames show (a fused scan's table is off by as much):
// the refinement finds how far, and the sphere on it stays where it is. Held where the twin has
// it, the table draws the frames' corrections, and the sphere with them.
TEST(MeshRefine, TheTablesHeightIsTakenFromTheFrames) {
  const Mesh truth = Sphere([](const Eigen::Vector3d&) { return kRadius; }, TrueColour);
  std::vector<core::Pose> truths;
  std::vector<RefineView> views = HandCameraViews(truth, &truths);
  for (auto& v : views) {
    v.table_from = 0;  // the fixed mesh is the table alone
    v.fixed.vertices = v.fixed.vertices - torch::tensor({0.0, 0.0, 0.002}, torch::kFloat64);
  }
  auto centre_error_mm = [&](const Mesh& m) {
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    for (const auto& v : m.vertices) c += v;
    return 1000 * (c / double(m.vertices.size()) - kCentre).norm();
  };
  MeshRefineOptions options;
  const MeshRefinement found = RefineMeshes({truth}, views, options);
  options.table_height = false;
  const MeshRefinement held = RefineMeshes({truth}, views, options);
  std::printf(
      "table found %.2f mm up; the sphere's centre %.2f mm off (%.2f mm with the table "
      "held); depth error %.2f (%.2f) mm\n",
      found.table_lift_mm, centre_error_mm(found.meshes[0]), centre_error_mm(held.meshes[0]),
      found.depth_error_after, held.depth_error_after);
  EXPECT_NEAR(found.table_lift_mm, 2, 0.3);
  EXPECT_EQ(held.table_lift_mm, 0);
  EXPECT_LT(centre_error_mm(found.meshes[0]), 0.5 * centre_error_mm(held.meshes[0]));
  EXPECT_LT(found.depth_error_after, held.depth_error_after);
}

// A block with a smaller one on top, off its middle (so that every turn shows), finely
// triangulated, coloured by height.
Mesh SteppedBlock() {
  Mesh block;
  for (const auto& [centre, size] :
       {std::pair{Eigen::Vector3d(0.5, 0, 0.07), Eigen::Vector3d(0.08, 0.05, 0.04)},
        std::pair{Eigen::Vector3d(0.52, 0.01, 0.1), Eigen::Vector3d(0.03, 0.025, 0.02)}}) {
    auto box = open3d::geometry::TriangleMesh::CreateBox(size.x(), size.y(), size.z());
    box->Translate(centre - 0.5 * size);
    box = box->SubdivideMidpoint(3);
    const int first = static_cast<int>(block.vertices.size());
    for (const auto& v : box->vertices_) {
      block.vertices.push_back(v);
      block.colors.push_back(Eigen::Vector3d(0.3, 0.5, 0.2 + 5 * (v.z() - 0.05)));
    }
    for (const auto& t : box->triangles_)
      block.triangles.emplace_back(first + t[0], first + t[1], first + t[2]);
  }
  return block;
}

Eigen::Vector3d Centroid(const Mesh& mesh) {
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (const auto& v : mesh.vertices) c += v;
  return c / static_cast<double>(mesh.vertices.size());
}

TEST(MeshRefine, AnObjectTheScanPutAFewMillimetresOffIsMovedBack) {
  const Mesh truth = SteppedBlock();
  // The scan: the same block 3.6 mm along the table and turned 3.2 deg about the upright, as a
  // scan misplaces an object.
  const Eigen::Vector3d centre = Centroid(truth);
  const core::Quat turn = core::Yaw(0.056);
  const core::Pose misplaced{centre + Eigen::Vector3d(0.003, -0.002, 0) - turn * centre, turn};
  Mesh scan = truth;
  for (auto& v : scan.vertices) v = misplaced * v;
  // Beside it, a ball the scan put where it is.
  Mesh ball = Sphere([](const Eigen::Vector3d&) { return 0.03; }, TrueColour);
  for (auto& v : ball.vertices) v += Eigen::Vector3d(0.02, -0.1, -0.02);
  Mesh scene = truth;
  AppendMesh(scene, ball);
  std::vector<RefineView> views;
  for (const auto& eye : {Eigen::Vector3d(0.15, 0.1, 0.35), Eigen::Vector3d(0.2, -0.2, 0.3),
                          Eigen::Vector3d(0.2, 0.25, 0.25), Eigen::Vector3d(0.3, 0.0, 0.5),
                          Eigen::Vector3d(0.7, 0.35, 0.3), Eigen::Vector3d(0.75, -0.3, 0.35)})
    views.push_back(View(scene, eye));
  // How far a mesh's vertices are from where the block's are, mm (the same vertices).
  auto error = [&](const Mesh& m) {
    double e = 0;
    for (size_t i = 0; i < m.vertices.size(); ++i) e += (m.vertices[i] - truth.vertices[i]).norm();
    return 1000 * e / m.vertices.size();
  };

  const MeshRefineOptions options;
  const MeshRefinement placed = PlaceObjects({scan, ball}, views, options);
  ASSERT_EQ(placed.object_corrections.size(), 2u);
  // The correction against the one that undoes the misplacement: at the block, mm and deg.
  const core::Pose left = placed.object_corrections[0] * misplaced;
  const double shift_mm = 1000 * (left * centre - centre).norm();
  const double turn_deg = Eigen::AngleAxisd(left.rotation).angle() * 180 / M_PI;
  // The offsets alone cannot move it back: they bend the surface where it should slide.
  const MeshRefinement bent = RefineMeshes({scan, ball}, views, options);
  std::printf(
      "vertex error %.2f mm -> %.2f placed (%.2f mm, %.2f deg left), %.2f with the offsets "
      "alone; depth %.2f -> %.2f mm\n",
      error(scan), error(placed.meshes[0]), shift_mm, turn_deg, error(bent.meshes[0]),
      placed.depth_error_before, placed.depth_error_after);
  EXPECT_GT(error(scan), 3.5);
  EXPECT_LT(shift_mm, 0.3);
  EXPECT_LT(turn_deg, 0.2);
  EXPECT_LT(error(placed.meshes[0]), 0.1 * error(scan));
  EXPECT_GT(error(bent.meshes[0]), 0.8 * error(scan));
  EXPECT_TRUE(bent.object_corrections.empty());
  EXPECT_EQ(placed.offset_max, 0);
  // The ball explained its pixels already: it keeps its pose, exactly.
  EXPECT_TRUE(placed.object_placed[0]);
  EXPECT_FALSE(placed.object_placed[1]);
  EXPECT_EQ(placed.meshes[1].vertices, ball.vertices);
  EXPECT_LT(placed.object_errors_after[0], 0.1 * placed.object_errors_before[0]);
}

TEST(MeshRefine, IsDeterministic) {
  const Mesh truth = Sphere([](const Eigen::Vector3d&) { return kRadius; }, TrueColour);
  const Mesh scan =
      Sphere([](const Eigen::Vector3d& d) { return kRadius + 0.003 * d.x(); }, TrueColour);
  const std::vector<RefineView> views = {View(truth, {0.15, 0.1, 0.35}),
                                         View(truth, {0.2, -0.2, 0.3})};
  MeshRefineOptions options;
  options.iterations = 8;
  const MeshRefinement a = RefineMeshes({scan}, views, options);
  const MeshRefinement b = RefineMeshes({scan}, views, options);
  EXPECT_EQ(a.meshes[0].vertices, b.meshes[0].vertices);
  EXPECT_EQ(a.meshes[0].colors, b.meshes[0].colors);
  EXPECT_EQ(a.loss, b.loss);
  EXPECT_NE(a.meshes[0].vertices, scan.vertices);
}

TEST(MeshRefine, AFrameIsReducedToBlockMediansWithItsIntrinsics) {
  const core::PinholeIntrinsics k{4, 4, 10, 10, 1.5, 1.5};
  std::vector<float> depth = {1, 2, 0, 0,  //
                              3, 4, 6, 5,  //
                              0, 0, 7, 7,  //
                              0, 9, 7, 8};
  std::vector<uint8_t> rgb(48, 51);
  const RefineView view = ReduceFrame(k, core::Pose(), depth, rgb, 2);
  EXPECT_EQ(view.intrinsics.width, 2);
  EXPECT_DOUBLE_EQ(view.intrinsics.fx, 5);
  EXPECT_DOUBLE_EQ(view.intrinsics.cx, 0.5);  // the middle, as 1.5 was of 4 pixels
  const auto d = view.depth.accessor<double, 2>();
  EXPECT_EQ(d[0][0], 3);  // the upper median of 1, 2, 3, 4
  EXPECT_EQ(d[0][1], 6);  // the upper median of 5, 6: half the block returned
  EXPECT_EQ(d[1][0], 0);  // fewer than half did
  EXPECT_EQ(d[1][1], 7);
  EXPECT_NEAR(view.rgb[0][0][0].item<double>(), 0.2, 1e-12);
  EXPECT_THROW(ReduceFrame(k, core::Pose(), std::vector<float>(3), rgb, 2), core::Error);
}

TEST(MeshRefine, NoViewOfTheMeshesIsAClearError) {
  const Mesh truth = Sphere([](const Eigen::Vector3d&) { return kRadius; }, TrueColour);
  RefineView away = View(truth, {0.2, 0.1, 0.3});
  away.camera_to_base = LookAt({0.2, 0.1, 0.3});
  away.camera_to_base.rotation =
      away.camera_to_base.rotation * core::Quat(Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()));
  try {
    RefineMeshes({truth}, {away}, MeshRefineOptions{});
    FAIL() << "no error";
  } catch (const core::ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("frames"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace twinforge::real2sim
