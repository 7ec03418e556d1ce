#include "real2sim/calibrate/calibrate.h"

#include <open3d/Open3D.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <vector>

#include "core/config.h"
#include "core/error.h"
#include "core/fs.h"
#include "core/image.h"
#include "core/rng.h"
#include "real2sim/calibrate/losses.h"
#include "real2sim/calibrate/soft_render.h"
#include "real2sim/calibrate/twin_geometry.h"
#include "real2sim/recipe.h"
#include "real2sim/segment.h"
#include "sim/camera.h"
#include "sim/env.h"
#include "sim/geom_scene.h"

namespace twinforge::real2sim {
namespace {

const auto kDouble = torch::TensorOptions().dtype(torch::kFloat64);

// Pixels' camera-frame rays (x/z, y/z, 1) for an image, [H, W, 3].
torch::Tensor Rays(const core::PinholeIntrinsics& k) {
  auto rays = torch::ones({k.height, k.width, 3}, kDouble);
  auto a = rays.accessor<double, 3>();
  for (int r = 0; r < k.height; ++r) {
    for (int c = 0; c < k.width; ++c) {
      a[r][c][0] = (c - k.cx) / k.fx;
      a[r][c][1] = (r - k.cy) / k.fy;
    }
  }
  return rays;
}

// One real frame, ready to compare with renders.
struct RealFrame {
  core::Pose reported;
  core::PinholeIntrinsics intrinsics;
  torch::Tensor depth;  // [H, W] m, 0 = no return
  torch::Tensor rgb;    // [H, W, 3] in [0, 1]
  RasterMesh twin;      // the twin posed as the robot was
  torch::Tensor arm;    // [V, 3] per twin vertex: 1 on the robot (known exactly), 0 elsewhere
  torch::Tensor rays;   // [H * W, 3] each pixel's (x/z, y/z, 1), for back-projecting depth
};

RealFrame ReadFrame(const core::Scan& scan, size_t i, TwinGeometry& geometry) {
  const core::ScanFrameInfo& info = scan.frames[i];
  RealFrame frame;
  frame.reported = info.camera_to_base;
  frame.intrinsics = info.intrinsics;
  const core::Image depth = core::ReadPng(scan.dir / info.depth);
  const core::Image color = core::ReadPng(scan.dir / info.color);
  const int w = info.intrinsics.width, h = info.intrinsics.height;
  if (depth.width != w || depth.height != h || depth.bit_depth != 16 || depth.channels != 1)
    throw core::ConfigError((scan.dir / info.depth).string(), "depth",
                            "a 16-bit grey image of " + std::to_string(w) + "x" +
                                std::to_string(h) + " (the frame's intrinsics)");
  if (color.width != w || color.height != h || color.channels < 3)
    throw core::ConfigError((scan.dir / info.color).string(), "color",
                            "an RGB image of " + std::to_string(w) + "x" + std::to_string(h));
  frame.depth = torch::empty({h, w}, kDouble);
  frame.rgb = torch::empty({h, w, 3}, kDouble);
  auto da = frame.depth.accessor<double, 2>();
  auto ca = frame.rgb.accessor<double, 3>();
  const auto* mm = reinterpret_cast<const uint16_t*>(depth.bytes.data());
  for (int r = 0; r < h; ++r) {
    for (int c = 0; c < w; ++c) {
      da[r][c] = mm[r * w + c] / scan.depth_scale;
      for (int k = 0; k < 3; ++k)
        ca[r][c][k] = color.bytes[(r * w + c) * color.channels + k] / 255.0;
    }
  }
  frame.twin = geometry.Posed(info.joint_positions, info.gripper_width);
  const mjModel* m = geometry.model();
  const int mount = m ? mj_name2id(m, mjOBJ_BODY, "robot_mount") : -1;
  frame.arm = geometry
                  .Posed(info.joint_positions, info.gripper_width,
                         [&](int g) {
                           return sim::InSubtree(m, m->geom_bodyid[g], mount)
                                      ? Eigen::Vector3d::Ones().eval()
                                      : Eigen::Vector3d::Zero().eval();
                         })
                  .colors;
  frame.rays = Rays(info.intrinsics).reshape({-1, 3});
  return frame;
}

// Up to `count` of the flat indices where `mask` is set, drawn at random.
torch::Tensor Draw(const torch::Tensor& mask, int count, core::Rng& rng) {
  const auto where = torch::nonzero(mask.reshape(-1)).reshape(-1);
  const int64_t n = where.size(0);
  if (n <= count) return where;
  std::vector<int64_t> pick(count);
  for (int i = 0; i < count; ++i) pick[i] = static_cast<int64_t>(rng.Uniform(0, 1) * n) % n;
  return where.index_select(
      0,
      torch::from_blob(pick.data(), {count}, torch::TensorOptions().dtype(torch::kInt64)).clone());
}

// The twin seen from `pose` with edges a third of a pixel soft: for scores and pictures.
SoftImage SharpImage(const RealFrame& frame, const core::Pose& pose) {
  torch::NoGradGuard no_grad;
  SoftRasterOptions sharp;
  sharp.sigma = 0.3;
  return SoftRasterize(frame.twin, frame.intrinsics, ToTensor(pose), sharp);
}

// How well `image` (the twin's, from SharpImage) matches the frame's depth.
FrameFit Fit(const RealFrame& frame, const SoftImage& image, double outlier) {
  torch::NoGradGuard no_grad;
  const auto seen = (frame.depth > 0) & (image.silhouette > 0.5);
  const auto error = (image.depth - frame.depth).abs().masked_select(seen);
  FrameFit fit;
  const int64_t returns = (frame.depth > 0).sum().item<int64_t>();
  const auto close = error.masked_select(error < outlier);
  fit.inliers = returns > 0 ? static_cast<double>(close.size(0)) / returns : 0;
  fit.median_depth_error = close.size(0) > 0 ? close.median().item<double>() : outlier;
  return fit;
}

FrameFit Fit(const RealFrame& frame, const core::Pose& pose, double outlier) {
  return Fit(frame, SharpImage(frame, pose), outlier);
}

// The real sensor's noise, from the frames against the twin seen from the calibrated pose:
// where the twin shows a surface, the share of pixels with no return at the twin's depth edges
// and elsewhere; and the spread of the depth step between horizontal neighbours inside
// surfaces, less the twin's own step there (what is left is the two pixels' noise, sqrt(2)
// sigma; a robust spread, so that the scan's own errors count little).
// `images[i]` is frame i's twin from SharpImage at the calibrated pose.
sim::DepthNoise EstimateNoise(const std::vector<RealFrame>& frames,
                              const std::vector<SoftImage>& images, double outlier) {
  torch::NoGradGuard no_grad;
  sim::DepthNoise noise;
  int64_t edges = 0, edges_lost = 0, inside = 0, inside_lost = 0;
  std::vector<double> steps;
  for (size_t i = 0; i < frames.size(); ++i) {
    const RealFrame& f = frames[i];
    const SoftImage& image = images[i];
    const int w = f.intrinsics.width, h = f.intrinsics.height;
    const torch::Tensor twin_depth = image.depth.contiguous(),
                        silhouette = image.silhouette.contiguous();
    const auto twin = twin_depth.accessor<double, 2>();
    const auto shown = silhouette.accessor<double, 2>();
    const auto real = f.depth.accessor<double, 2>();
    auto surface = [&](int r, int c) { return shown[r][c] > 0.5 && twin[r][c] > 0; };
    // The twin's depth, with no return off its silhouette.
    std::vector<float> seen(static_cast<size_t>(w) * h, 0.0f);
    for (int r = 0; r < h; ++r)
      for (int c = 0; c < w; ++c)
        if (surface(r, c)) seen[r * w + c] = static_cast<float>(twin[r][c]);
    const std::vector<uint8_t> is_edge = sim::DepthEdges(seen.data(), w, h, noise.edge_jump);
    auto edge = [&](int r, int c) { return is_edge[r * w + c] != 0; };
    for (int r = 0; r < h; ++r)
      for (int c = 0; c < w; ++c) {
        if (!surface(r, c)) continue;
        const bool lost = real[r][c] <= 0;
        if (edge(r, c)) {
          ++edges;
          edges_lost += lost;
          continue;
        }
        ++inside;
        inside_lost += lost;
        if (c + 1 < w && surface(r, c + 1) && !edge(r, c + 1) && !lost && real[r][c + 1] > 0 &&
            std::abs(real[r][c] - twin[r][c]) < outlier &&
            std::abs(real[r][c + 1] - twin[r][c + 1]) < outlier)
          steps.push_back((real[r][c + 1] - real[r][c]) - (twin[r][c + 1] - twin[r][c]));
      }
  }
  if (edges > 0) noise.edge_dropout = double(edges_lost) / edges;
  if (inside > 0) noise.dropout = double(inside_lost) / inside;
  if (steps.size() >= 10) {
    auto median = [](std::vector<double> v) {
      std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
      return v[v.size() / 2];
    };
    const double centre = median(steps);
    for (double& d : steps) d = std::abs(d - centre);
    noise.sigma0 = 1.4826 * median(steps) / std::sqrt(2.0);
  }
  return noise;
}

// Surfaces the real sensor loses more returns on than the rest (shiny metal, dark plastic). For
// each scene geom the twin (ray-cast from the calibrated pose, `depth[i]` and `geom[i]` for frame
// i) shows on enough pixels: the returns the frames kept there, against what `noise`'s edge and
// surface dropouts alone would keep. A geom is listed when it kept at most 90% of that, and the
// shortfall is over 3 standard deviations of those dropouts' own spread.
std::vector<sim::SurfaceDropout> EstimateSurfaceDropout(
    const std::vector<RealFrame>& frames, const std::vector<std::vector<float>>& depth,
    const std::vector<std::vector<int>>& geom, const sim::DepthNoise& noise, const mjModel* m) {
  torch::NoGradGuard no_grad;
  const int mount = mj_name2id(m, mjOBJ_BODY, "robot_mount");
  struct Count {
    int pixels = 0;
    double kept = 0, expected = 0, variance = 0;
  };
  std::vector<Count> counts(m->ngeom);
  for (size_t i = 0; i < frames.size(); ++i) {
    const int w = frames[i].intrinsics.width, h = frames[i].intrinsics.height;
    const auto real = frames[i].depth.contiguous();
    const double* r = real.data_ptr<double>();
    const std::vector<uint8_t> edges = sim::DepthEdges(depth[i].data(), w, h, noise.edge_jump);
    for (int p = 0; p < w * h; ++p) {
      const int g = geom[i][p];
      if (g < 0 || (mount >= 0 && sim::InSubtree(m, m->geom_bodyid[g], mount))) continue;
      const double lose = edges[p] ? noise.edge_dropout : noise.dropout;
      Count& c = counts[g];
      ++c.pixels;
      c.kept += r[p] > 0;
      c.expected += 1 - lose;
      c.variance += lose * (1 - lose);
    }
  }
  std::vector<sim::SurfaceDropout> out;
  for (int g = 0; g < m->ngeom; ++g) {
    const Count& c = counts[g];
    const char* name = mj_id2name(m, mjOBJ_GEOM, g);
    if (!name || c.pixels < 20) continue;
    const double dropout = 1 - c.kept / c.expected;
    spdlog::debug("calibrate: '{}': {} pixels, {:.0f} returns kept, {:.1f} expected", name,
                  c.pixels, c.kept, c.expected);
    if (dropout < 0.1 || c.expected - c.kept < 3 * std::sqrt(c.variance + 1)) continue;
    out.push_back({name, std::min(dropout, 0.95)});
    spdlog::info("calibrate: the sensor loses {:.0f}% of the returns on '{}' ({} pixels)",
                 100 * dropout, name, c.pixels);
  }
  return out;
}

// Open3D point-to-plane ICP of the real clouds (from the reported pose) onto the twin's surface:
// the correction it implies for the camera (fixed mount: one for all frames).
core::Pose IcpCorrection(const std::vector<RealFrame>& frames, double outlier) {
  auto source = std::make_shared<open3d::geometry::PointCloud>();
  auto target = std::make_shared<open3d::geometry::PointCloud>();
  for (const RealFrame& f : frames) {
    const auto& k = f.intrinsics;
    const auto da = f.depth.accessor<double, 2>();
    for (int r = 0; r < k.height; ++r) {
      for (int c = 0; c < k.width; ++c) {
        const double z = da[r][c];
        if (z <= 0) continue;
        source->points_.push_back(f.reported *
                                  Eigen::Vector3d((c - k.cx) / k.fx * z, (r - k.cy) / k.fy * z, z));
      }
    }
    Mesh twin;
    const auto v = f.twin.vertices.contiguous();
    const auto t = f.twin.faces.contiguous();
    for (int64_t i = 0; i < v.size(0); ++i)
      twin.vertices.emplace_back(v[i][0].item<double>(), v[i][1].item<double>(),
                                 v[i][2].item<double>());
    const auto ta = t.accessor<int64_t, 2>();
    for (int64_t i = 0; i < t.size(0); ++i)
      twin.triangles.emplace_back(static_cast<int>(ta[i][0]), static_cast<int>(ta[i][1]),
                                  static_cast<int>(ta[i][2]));
    std::vector<Eigen::Vector3d> normals;
    const auto points = SampleSurface(twin, 20000, 7, &normals);
    target->points_.insert(target->points_.end(), points.begin(), points.end());
    target->normals_.insert(target->normals_.end(), normals.begin(), normals.end());
  }
  namespace reg = open3d::pipelines::registration;
  const auto result = reg::RegistrationICP(*source, *target, outlier, Eigen::Matrix4d::Identity(),
                                           reg::TransformationEstimationPointToPlane(),
                                           reg::ICPConvergenceCriteria(1e-7, 1e-7, 60));
  const core::Pose moved = core::Pose::FromMatrix(result.transformation_);
  return frames.front().reported.Inverse() * moved * frames.front().reported;
}

using Vector6 = Eigen::Matrix<double, 6, 1>;

torch::Tensor ToTensor6(const Vector6& v) {
  return torch::from_blob(const_cast<double*>(v.data()), {6}, kDouble).clone();
}

// The twin rendered from the reported pose moved by `delta`, with the arm's share of each pixel
// as its colour (rgb channel 0), for the depth residuals and their weights.
SoftImage RenderArmShare(const RealFrame& f, const Vector6& delta,
                         const SoftRasterOptions& raster) {
  return SoftRasterize({f.twin.vertices, f.twin.faces, f.arm}, f.intrinsics,
                       PerturbPose(f.reported, ToTensor6(delta)), raster);
}

// Levenberg-Marquardt on the frames' depth residuals: the objective is the mean Huber depth
// error of DepthLoss (pixels the twin does not cover, or misses by more than `outlier`, cost a
// constant), the arm's pixels weighted arm_weight times (its shape and pose are known exactly,
// the scene's only as well as its scan), plus the prior; minimised by iteratively reweighted
// Gauss-Newton steps, damped until a step lowers it. Each pixel's derivative is a central
// difference of sharp renders; pixels where a difference jumps (an edge crossed the pixel) are
// left out of that step. Unlike Adam's steps of a fixed size, a step here is as long as the data
// say, and it stops where no step lowers the loss instead of drifting along a direction the
// frames hardly see.
Vector6 GaussNewton(const std::vector<RealFrame>& frames, const CalibrateOptions& o,
                    const Vector6& start, double* final_cost, std::vector<double>* curve,
                    core::Progress* progress) {
  torch::NoGradGuard no_grad;
  SoftRasterOptions raster;
  raster.sigma = o.gauss_newton_sigma;
  raster.cutoff = 3;
  const double huber = 0.005;  // m: quadratic below, linear above
  const double step = 1e-5;    // rad and m, for the central differences
  const double jump = 30;      // m per rad (or per m): a depth that moves faster crossed an edge
  // The prior as in the Adam objective: a move of prior_* costs as much as 1 mm mean error.
  const double millimetre = 0.5e-6;
  Vector6 prior;
  prior << Eigen::Vector3d::Constant(2 * millimetre / (o.prior_rotation * o.prior_rotation)),
      Eigen::Vector3d::Constant(2 * millimetre / (o.prior_translation * o.prior_translation));
  // A pixel's weight: 1 on the scene, arm_weight on the arm.
  auto render = [&](const RealFrame& f, const Vector6& delta, torch::Tensor* weight) {
    SoftImage image = RenderArmShare(f, delta, raster);
    *weight = 1 + (o.arm_weight - 1) * image.rgb.select(2, 0);
    return image;
  };
  auto cost = [&](const Vector6& delta) {
    double sum = 0;
    for (const RealFrame& f : frames) {
      torch::Tensor weight;
      const SoftImage image = render(f, delta, &weight);
      sum += DepthLoss(image.depth, image.silhouette, f.depth, huber, o.outlier, weight)
                 .item<double>();
    }
    return sum / frames.size() + 0.5 * delta.dot(prior.asDiagonal() * delta);
  };
  Vector6 delta = start;
  double current = cost(delta);
  double damping = 1e-3;
  for (int iteration = 0; iteration < o.gauss_newton_iterations; ++iteration) {
    Eigen::Matrix<double, 6, 6> h = Eigen::Matrix<double, 6, 6>::Zero();
    Vector6 g = Vector6::Zero();
    for (const RealFrame& f : frames) {
      torch::Tensor weight;
      const SoftImage image = render(f, delta, &weight);
      const auto residual = image.depth - f.depth;
      auto use = (f.depth > 0) & (image.silhouette > 0.99) & (residual.abs() < o.outlier);
      std::vector<torch::Tensor> columns;
      for (int k = 0; k < 6; ++k) {
        Vector6 plus = delta, minus = delta;
        plus[k] += step;
        minus[k] -= step;
        const SoftImage a = RenderArmShare(f, plus, raster), b = RenderArmShare(f, minus, raster);
        const auto column = (a.depth - b.depth) / (2 * step);
        use = use & (a.silhouette > 0.99) & (b.silhouette > 0.99) & (column.abs() < jump);
        columns.push_back(column);
      }
      const double returns = std::max<int64_t>(1, (f.depth > 0).sum().item<int64_t>());
      const auto r = residual.masked_select(use);
      if (r.size(0) == 0) continue;
      const auto pixel_weight = weight.masked_select(use);
      const auto jacobian =
          torch::stack({columns[0].masked_select(use), columns[1].masked_select(use),
                        columns[2].masked_select(use), columns[3].masked_select(use),
                        columns[4].masked_select(use), columns[5].masked_select(use)},
                       1);
      // Huber as reweighted least squares: w = 1 inside the width, width / |r| beyond.
      const auto w = (huber / r.abs()).clamp_max(1) * pixel_weight / (returns * frames.size());
      const auto jt_w = (jacobian * w.unsqueeze(1)).t().contiguous();
      const auto hh = torch::matmul(jt_w, jacobian).contiguous();
      const auto gg = torch::matmul(jt_w, r).contiguous();
      h += Eigen::Map<const Eigen::Matrix<double, 6, 6, Eigen::RowMajor>>(hh.data_ptr<double>());
      g += Eigen::Map<const Vector6>(gg.data_ptr<double>());
    }
    g += prior.asDiagonal() * delta;
    h += prior.asDiagonal();
    bool moved = false;
    for (int attempt = 0; attempt < 8 && !moved; ++attempt) {
      Eigen::Matrix<double, 6, 6> a = h;
      a.diagonal() *= 1 + damping;
      const Vector6 next = delta - a.ldlt().solve(g);
      const double c = cost(next);
      if (c < current) {
        moved = (next - delta).cwiseAbs().maxCoeff() > 1e-7;
        delta = next;
        current = c;
        damping = std::max(1e-6, damping / 3);
        if (!moved) break;
      } else {
        damping *= 4;
      }
    }
    curve->push_back(current);
    if (progress) progress->Advance(1, "loss " + std::to_string(current));
    if (!moved) break;
  }
  *final_cost = current;
  return delta;
}

// Adam on the correction, coarse to fine, on the depth and EMD losses (and the colour loss).
core::Pose AdamCorrection(const std::vector<RealFrame>& frames, const CalibrateOptions& options,
                          std::vector<double>* curve, core::Progress* progress) {
  core::Rng rng(options.seed, 0xca1b);
  auto delta = torch::zeros({6}, kDouble).requires_grad_(true);
  torch::optim::Adam adam({delta}, torch::optim::AdamOptions(options.learning_rate));
  const int stages = static_cast<int>(options.sigmas.size());
  // What 1 mm of mean depth error costs in the depth term (Huber, quadratic below 1 cm).
  const double millimetre = options.depth_weight * 0.5 * 1e-6;
  for (int step = 0; step < options.iterations; ++step) {
    // Cosine decay of the step: the last steps settle instead of wandering.
    static_cast<torch::optim::AdamOptions&>(adam.param_groups()[0].options())
        .lr(options.learning_rate * 0.5 * (1 + std::cos(M_PI * step / options.iterations)));
    SoftRasterOptions raster;
    raster.sigma = options.sigmas[std::min(stages - 1, step * stages / options.iterations)];
    raster.cutoff = 3;
    torch::Tensor loss = torch::zeros({}, kDouble);
    for (const RealFrame& f : frames) {
      const CameraTensor pose = PerturbPose(f.reported, delta);
      const SoftImage image = SoftRasterize(f.twin, f.intrinsics, pose, raster);
      loss = loss + options.depth_weight *
                        DepthLoss(image.depth, image.silhouette, f.depth, 0.01, options.outlier);
      if (options.rgb_weight > 0)
        loss = loss + options.rgb_weight * RgbLoss(image.rgb, image.silhouette, f.rgb,
                                                   (f.depth > 0).to(torch::kFloat64));
      // EMD between the real returns and the twin's visible surface, both in the base frame
      // (the real ones moved by the pose; the twin's where the render puts them).
      const auto covered = image.silhouette.detach() > 0.5;
      const auto real_index = Draw((f.depth > 0) & covered, options.emd_points, rng);
      const auto twin_index = Draw(covered, options.emd_points, rng);
      if (real_index.size(0) < 16 || twin_index.size(0) < 16) continue;
      const auto real_cam = f.rays.index_select(0, real_index) *
                            f.depth.reshape(-1).index_select(0, real_index).unsqueeze(1);
      const auto twin_cam =
          f.rays.index_select(0, twin_index) *
          image.depth.detach().reshape(-1).index_select(0, twin_index).unsqueeze(1);
      const CameraTensor fixed = ToTensor(ApplyDelta(f.reported, delta));
      const auto real_base = torch::matmul(real_cam, pose.rotation.t()) + pose.translation;
      const auto twin_base = torch::matmul(twin_cam, fixed.rotation.t()) + fixed.translation;
      loss = loss + options.emd_weight * SinkhornEmd(real_base, twin_base, 0.003, 60);
    }
    loss = loss / static_cast<double>(frames.size()) +
           millimetre * ((delta.slice(0, 0, 3) / options.prior_rotation).square().sum() +
                         (delta.slice(0, 3, 6) / options.prior_translation).square().sum());
    adam.zero_grad();
    loss.backward();
    adam.step();
    curve->push_back(loss.item<double>());
    if (progress) progress->Advance(1, "loss " + std::to_string(curve->back()));
  }
  return ApplyDelta(core::Pose::Identity(), delta);
}

nlohmann::json ToJson(const core::Pose& p) {
  const Eigen::Vector3d r = core::LogMap(p.rotation);
  return {{"translation_mm",
           {p.translation.x() * 1e3, p.translation.y() * 1e3, p.translation.z() * 1e3}},
          {"rotation_deg", {r.x() * 180 / M_PI, r.y() * 180 / M_PI, r.z() * 180 / M_PI}},
          {"distance_mm", p.translation.norm() * 1e3},
          {"angle_deg", r.norm() * 180 / M_PI}};
}

nlohmann::json ToJson(const std::vector<FrameFit>& fits) {
  nlohmann::json out = nlohmann::json::array();
  for (const FrameFit& f : fits)
    out.push_back({{"median_depth_error_mm", f.median_depth_error * 1e3}, {"inliers", f.inliers}});
  return out;
}

}  // namespace

CameraCalibration CalibrateCamera(const sim::TaskSpec& twin_task, const core::Scan& scan,
                                  const CalibrateOptions& options, core::Progress* progress) {
  if (scan.frames.empty())
    throw core::ConfigError((scan.dir / "frames.json").string(), "frames", "at least one frame");
  const auto start = std::chrono::steady_clock::now();
  TwinGeometry geometry(twin_task, options.mesh_triangles);
  std::vector<RealFrame> frames;
  for (size_t i = 0; i < scan.frames.size(); ++i) frames.push_back(ReadFrame(scan, i, geometry));

  CameraCalibration out;
  for (const RealFrame& f : frames) {
    out.before.push_back(Fit(f, f.reported, options.outlier));
    if (out.before.back().inliers < 0.05)
      throw core::ConfigError(
          (scan.dir / scan.frames[out.before.size() - 1].depth).string(), "depth",
          "a frame that shows the twin's scene (under 5% of its returns are "
          "within " +
              std::to_string(options.outlier) + " m of the twin seen from the reported pose)");
  }

  out.icp_correction = IcpCorrection(frames, options.outlier);
  if (options.solver == "gauss_newton") {
    // From the reported pose and from ICP's answer; the lower loss wins. Each run stops in the
    // nearest minimum, and the two starts fall into different ones as often as not.
    std::vector<Vector6> starts(1, Vector6::Zero());
    if (options.start_from_icp) {
      starts.emplace_back();
      starts.back() << core::LogMap(out.icp_correction.rotation), out.icp_correction.translation;
    }
    double best = std::numeric_limits<double>::infinity();
    for (const Vector6& start : starts) {
      double loss = 0;
      std::vector<double> curve;
      const Vector6 delta = GaussNewton(frames, options, start, &loss, &curve, progress);
      spdlog::debug("calibrate: a start ends at loss {:.6e}, [{:.1f} {:.1f} {:.1f}] mm", loss,
                    1e3 * delta[3], 1e3 * delta[4], 1e3 * delta[5]);
      if (loss < best) {
        best = loss;
        out.correction = ApplyDelta(core::Pose::Identity(), ToTensor6(delta));
        out.loss = curve;
      }
    }
  } else {
    out.correction = AdamCorrection(frames, options, &out.loss, progress);
  }
  std::vector<SoftImage> calibrated;
  for (const RealFrame& f : frames) {
    calibrated.push_back(SharpImage(f, f.reported * out.correction));
    out.after.push_back(Fit(f, calibrated.back(), options.outlier));
    out.icp.push_back(Fit(f, f.reported * out.icp_correction, options.outlier));
  }
  out.noise = EstimateNoise(frames, calibrated, options.outlier);
  std::vector<std::vector<float>> cast_depth(frames.size());
  std::vector<std::vector<int>> cast_geom(frames.size());
  for (size_t i = 0; i < frames.size(); ++i)
    geometry.RayCast(scan.frames[i].joint_positions, scan.frames[i].gripper_width,
                     {frames[i].intrinsics, frames[i].reported * out.correction}, &cast_depth[i],
                     &cast_geom[i]);
  out.noise.surfaces =
      EstimateSurfaceDropout(frames, cast_depth, cast_geom, out.noise, geometry.model());
  out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return out;
}

std::vector<FrameFit> FitFrames(const sim::TaskSpec& twin_task, const core::Scan& scan,
                                const core::Pose& correction, const CalibrateOptions& options) {
  TwinGeometry geometry(twin_task, options.mesh_triangles);
  std::vector<FrameFit> fits;
  for (size_t i = 0; i < scan.frames.size(); ++i) {
    const RealFrame f = ReadFrame(scan, i, geometry);
    fits.push_back(Fit(f, f.reported * correction, options.outlier));
  }
  return fits;
}

nlohmann::json ToJson(const CameraCalibration& c) {
  return {{"correction", ToJson(c.correction)},
          {"correction_array", sim::CorrectionArray(c.correction)},
          {"icp_correction", ToJson(c.icp_correction)},
          {"frames_before", ToJson(c.before)},
          {"frames_after", ToJson(c.after)},
          {"frames_icp", ToJson(c.icp)},
          {"depth_noise", core::ToJson(c.noise)},
          {"loss_first", c.loss.empty() ? 0.0 : c.loss.front()},
          {"loss_last", c.loss.empty() ? 0.0 : c.loss.back()},
          {"steps", c.loss.size()},
          {"seconds", c.seconds}};
}

void WriteCalibratedTwin(const std::filesystem::path& twin_dir, const core::Scan& scan,
                         const CameraCalibration& calibration, const CalibrateOptions& options,
                         const std::filesystem::path& out) {
  namespace fs = std::filesystem;
  if (fs::exists(out) && fs::equivalent(out, twin_dir))
    throw core::ConfigError(out.string(), "out", "a directory other than the twin's own");
  core::EnsureDirectory(out);
  fs::copy(twin_dir, out, fs::copy_options::recursive | fs::copy_options::overwrite_existing);
  sim::TaskSpec task = sim::LoadTaskSpec((out / "task.yaml").string());
  task.camera.correction = sim::CorrectionArray(calibration.correction);
  task.camera.noise = calibration.noise;
  WriteTwinTask(task, out);

  // Before/after images: real colour | twin before | twin after | depth error before | after
  // (black: agree; white: off by `outlier` or more), one row per frame.
  const fs::path report = out / "calibration";
  core::EnsureDirectory(report);
  TwinGeometry geometry(sim::LoadTaskSpec((twin_dir / "task.yaml").string()),
                        options.mesh_triangles);
  for (size_t i = 0; i < scan.frames.size(); ++i) {
    const RealFrame f = ReadFrame(scan, i, geometry);
    const core::Image image =
        BeforeAfterPicture(f.rgb, f.depth, SharpImage(f, f.reported),
                           SharpImage(f, f.reported * calibration.correction), options.outlier);
    char name[48];
    std::snprintf(name, sizeof(name), "frame_%02zu.png", i);
    core::WritePng(report / name, image);
  }
  nlohmann::json json = ToJson(calibration);
  json["frames"] = scan.dir.string();
  json["twin"] = twin_dir.string();
  core::WriteFileAtomic(report / "calibration.json", json.dump(2));
}

}  // namespace twinforge::real2sim
