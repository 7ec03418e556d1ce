#include "real2sim/calibrate/soft_render.h"

#include <gtest/gtest.h>

#include <functional>

#include "real2sim/calibrate/losses.h"

namespace twinforge::real2sim {
namespace {

const auto kDouble = torch::TensorOptions().dtype(torch::kFloat64);

// Two boxes on a table top, base frame (z up), with a colour per vertex.
RasterMesh BoxesOnATable() {
  const Eigen::Vector3d grey(0.5, 0.5, 0.5);
  RasterMesh mesh = JoinMeshes({BoxMesh({0.5, 0.0, -0.02}, {0.9, 0.7, 0.04}, grey),     // the table
                                BoxMesh({0.45, -0.12, 0.06}, {0.12, 0.1, 0.12}, grey),  // a block
                                BoxMesh({0.6, 0.15, 0.04}, {0.08, 0.16, 0.08}, grey)});  // a bar
  mesh.colors = 0.2 + 0.6 * torch::rand({mesh.vertices.size(0), 3}, kDouble);
  return mesh;
}

core::PinholeIntrinsics Intrinsics(int width, int height) {
  core::PinholeIntrinsics k;
  k.width = width;
  k.height = height;
  k.fx = k.fy = 0.9 * width;
  k.cx = 0.5 * (width - 1);
  k.cy = 0.5 * (height - 1);
  return k;
}

// A camera in front of and above the table, looking at it (OpenCV axes).
core::Pose LookingAtTheTable() {
  const Eigen::Vector3d eye(1.25, 0.1, 0.6), target(0.5, 0.0, 0.0);
  const Eigen::Vector3d forward = (target - eye).normalized();
  const Eigen::Vector3d right = forward.cross(Eigen::Vector3d::UnitZ()).normalized();
  Eigen::Matrix3d r;
  r << right, forward.cross(right), forward;
  return {eye, core::Quat(r)};
}

// Central finite differences of `f` in every entry of `x` against autograd.
void ExpectGradientMatches(torch::Tensor x, const std::function<torch::Tensor(torch::Tensor)>& f,
                           double step, double tolerance) {
  auto input = x.clone().requires_grad_(true);
  f(input).backward();
  const auto analytic = input.grad().clone();
  auto flat = x.clone().reshape(-1);
  int compared = 0;
  for (int64_t i = 0; i < flat.size(0); ++i) {
    torch::NoGradGuard no_grad;
    const double keep = flat[i].item<double>();
    flat[i] = keep + step;
    const double up = f(flat.reshape(x.sizes())).item<double>();
    flat[i] = keep - step;
    const double down = f(flat.reshape(x.sizes())).item<double>();
    flat[i] = keep;
    const double numeric = (up - down) / (2 * step);
    const double a = analytic.reshape(-1)[i].item<double>();
    EXPECT_NEAR(a, numeric, tolerance * (1 + std::abs(numeric))) << "entry " << i;
    compared += std::abs(numeric) > 1e-6;
  }
  EXPECT_GT(compared, 0) << "the loss does not depend on this input at all";
}

// A loss that reads all three images at every pixel, with fixed random weights.
struct ImageLoss {
  torch::Tensor ws, wd, wc;
  explicit ImageLoss(const core::PinholeIntrinsics& k) {
    torch::manual_seed(3);
    ws = torch::rand({k.height, k.width}, kDouble);
    wd = torch::rand({k.height, k.width}, kDouble);
    wc = torch::rand({k.height, k.width, 3}, kDouble);
  }
  torch::Tensor operator()(const SoftImage& image) const {
    return (ws * image.silhouette).sum() + (wd * image.depth).sum() + (wc * image.rgb).sum();
  }
};

TEST(SoftRasterize, GradientsMatchFiniteDifferences) {
  torch::manual_seed(1);
  const RasterMesh mesh = BoxesOnATable();
  const auto k = Intrinsics(32, 24);
  const core::Pose pose = LookingAtTheTable();
  const ImageLoss loss(k);
  SoftRasterOptions options;
  options.sigma = 1.0;

  // Camera pose: rotation vector and translation in the camera frame.
  ExpectGradientMatches(
      torch::tensor({0.01, -0.02, 0.015, 0.01, 0.005, -0.01}, kDouble),
      [&](torch::Tensor delta) {
        return loss(SoftRasterize(mesh, k, PerturbPose(pose, delta), options));
      },
      1e-6, 2e-4);
  // The vertices of the block (8 corners).
  ExpectGradientMatches(
      mesh.vertices.slice(0, 8, 16).clone(),
      [&](torch::Tensor block) {
        RasterMesh m = mesh;
        m.vertices = torch::cat({mesh.vertices.slice(0, 0, 8), block, mesh.vertices.slice(0, 16)});
        return loss(SoftRasterize(m, k, ToTensor(pose), options));
      },
      1e-6, 2e-4);
  // Vertex colours.
  ExpectGradientMatches(
      mesh.colors.slice(0, 8, 16).clone(),
      [&](torch::Tensor colors) {
        RasterMesh m = mesh;
        m.colors = torch::cat({mesh.colors.slice(0, 0, 8), colors, mesh.colors.slice(0, 16)});
        return loss(SoftRasterize(m, k, ToTensor(pose), options));
      },
      1e-6, 2e-4);
}

TEST(SoftRasterize, ImagesShowWhatIsInFront) {
  const RasterMesh mesh = BoxesOnATable();
  const auto k = Intrinsics(64, 48);
  SoftRasterOptions options;
  options.sigma = 0.3;
  const SoftImage image = SoftRasterize(mesh, k, ToTensor(LookingAtTheTable()), options);
  // The block's top face centre, projected: depth there is the distance to the top, not the
  // table behind it.
  const core::Pose pose = LookingAtTheTable();
  const Eigen::Vector3d top = pose.Inverse() * Eigen::Vector3d(0.45, -0.12, 0.12);
  const int c = static_cast<int>(std::lround(k.fx * top.x() / top.z() + k.cx));
  const int r = static_cast<int>(std::lround(k.fy * top.y() / top.z() + k.cy));
  EXPECT_NEAR(image.depth[r][c].item<double>(), top.z(), 0.01);
  EXPECT_GT(image.silhouette[r][c].item<double>(), 0.99);
  // Everything on screen is inside [0, 1].
  EXPECT_GE(image.silhouette.min().item<double>(), 0);
  EXPECT_LE(image.silhouette.max().item<double>(), 1);
  EXPECT_GE(image.rgb.min().item<double>(), 0);
  EXPECT_LE(image.rgb.max().item<double>(), 1 + 1e-9);
}

TEST(SoftRasterize, RecoversAKnownCameraOffset) {
  torch::manual_seed(2);
  const RasterMesh mesh = BoxesOnATable();
  const auto k = Intrinsics(96, 72);
  const core::Pose truth = LookingAtTheTable();
  SoftRasterOptions sharp;
  sharp.sigma = 0.3;
  torch::NoGradGuard no_grad_target;
  const SoftImage target = SoftRasterize(mesh, k, ToTensor(truth), sharp);
  // Where the camera is believed to be: 3 cm and 5 degrees off.
  const core::Pose believed =
      truth *
      core::Pose{Eigen::Vector3d(0.018, -0.017, 0.017),
                 core::ExpMap(Eigen::Vector3d(0.05, -0.04, 0.05).normalized() * (5 * M_PI / 180))};
  auto delta = torch::zeros({6}, kDouble).requires_grad_(true);
  {
    torch::AutoGradMode grad(true);
    torch::optim::Adam adam({delta}, torch::optim::AdamOptions(0.004));
    for (int step = 0; step < 300; ++step) {
      SoftRasterOptions options;
      options.sigma = step < 150 ? 2.0 : step < 230 ? 1.0 : 0.5;
      const SoftImage image = SoftRasterize(mesh, k, PerturbPose(believed, delta), options);
      const auto loss = DepthLoss(image.depth, image.silhouette, target.depth, 0.01, 0.2) * 100 +
                        SilhouetteLoss(image.silhouette, target.silhouette);
      adam.zero_grad();
      loss.backward();
      adam.step();
    }
  }
  const core::Pose found = ApplyDelta(believed, delta);
  EXPECT_LT((found.translation - truth.translation).norm(), 0.005);
  EXPECT_LT(core::AngleBetween(found.rotation, truth.rotation) * 180 / M_PI, 1.0);
}

}  // namespace
}  // namespace twinforge::real2sim
