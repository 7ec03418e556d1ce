#include "real2sim/calibrate/soft_render.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

namespace twinforge::real2sim {
namespace {

const auto kDouble = torch::TensorOptions().dtype(torch::kFloat64);
const auto kLong = torch::TensorOptions().dtype(torch::kInt64);

torch::Tensor Skew(const torch::Tensor& w) {
  const auto zero = torch::zeros({}, kDouble);
  return torch::stack({zero, -w[2], w[1], w[2], zero, -w[0], -w[1], w[0], zero}).reshape({3, 3});
}

// Signed distance (px) from (px, py) to the edge a -> b, positive on the side of `sign`.
double EdgeDistance(double ax, double ay, double bx, double by, double px, double py, double sign) {
  const double e = (bx - ax) * (py - ay) - (by - ay) * (px - ax);
  return sign * e / std::sqrt((bx - ax) * (bx - ax) + (by - ay) * (by - ay) + 1e-12);
}

// The (pixel, triangle) pairs within the cutoff, found on plain numbers.
void FindPairs(const torch::Tensor& u, const torch::Tensor& v, const torch::Tensor& z,
               const torch::Tensor& faces, const core::PinholeIntrinsics& k,
               const SoftRasterOptions& options, std::vector<int64_t>& pixels,
               std::vector<int64_t>& triangles) {
  const auto ua = u.accessor<double, 1>(), va = v.accessor<double, 1>(),
             za = z.accessor<double, 1>();
  const auto f = faces.accessor<int64_t, 2>();
  const double reach = options.cutoff * options.sigma;
  for (int64_t t = 0; t < f.size(0); ++t) {
    const int64_t i0 = f[t][0], i1 = f[t][1], i2 = f[t][2];
    if (za[i0] < options.near || za[i1] < options.near || za[i2] < options.near) continue;
    const double x0 = ua[i0], y0 = va[i0], x1 = ua[i1], y1 = va[i1], x2 = ua[i2], y2 = va[i2];
    const double area2 = (x1 - x0) * (y2 - y0) - (y1 - y0) * (x2 - x0);
    if (std::abs(area2) < 1e-9) continue;
    const double sign = area2 > 0 ? 1.0 : -1.0;
    const int c0 = std::max(0, static_cast<int>(std::ceil(std::min({x0, x1, x2}) - reach)));
    const int c1 =
        std::min(k.width - 1, static_cast<int>(std::floor(std::max({x0, x1, x2}) + reach)));
    const int r0 = std::max(0, static_cast<int>(std::ceil(std::min({y0, y1, y2}) - reach)));
    const int r1 =
        std::min(k.height - 1, static_cast<int>(std::floor(std::max({y0, y1, y2}) + reach)));
    for (int r = r0; r <= r1; ++r) {
      for (int c = c0; c <= c1; ++c) {
        const double d = std::min({EdgeDistance(x0, y0, x1, y1, c, r, sign),
                                   EdgeDistance(x1, y1, x2, y2, c, r, sign),
                                   EdgeDistance(x2, y2, x0, y0, c, r, sign)});
        if (d <= -reach) continue;
        pixels.push_back(static_cast<int64_t>(r) * k.width + c);
        triangles.push_back(t);
      }
    }
  }
}

}  // namespace

RasterMesh BoxMesh(const Eigen::Vector3d& center, const Eigen::Vector3d& size,
                   const Eigen::Vector3d& color) {
  std::vector<double> v, c;
  for (int i = 0; i < 8; ++i) {
    for (int k = 0; k < 3; ++k) {
      v.push_back(center[k] + ((i >> k) & 1 ? 0.5 : -0.5) * size[k]);
      c.push_back(color[k]);
    }
  }
  // Corner i has bit k set when it is on the + side of axis k.
  const int64_t quads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4},
                               {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  std::vector<int64_t> f;
  for (const auto& q : quads) f.insert(f.end(), {q[0], q[1], q[2], q[0], q[2], q[3]});
  return {torch::from_blob(v.data(), {8, 3}, kDouble).clone(),
          torch::from_blob(f.data(), {12, 3}, kLong).clone(),
          torch::from_blob(c.data(), {8, 3}, kDouble).clone()};
}

RasterMesh JoinMeshes(const std::vector<RasterMesh>& meshes) {
  std::vector<torch::Tensor> v, f, c;
  int64_t offset = 0;
  for (const RasterMesh& m : meshes) {
    v.push_back(m.vertices);
    f.push_back(m.faces + offset);
    if (m.colors.defined()) c.push_back(m.colors);
    offset += m.vertices.size(0);
  }
  RasterMesh out{torch::cat(v), torch::cat(f), {}};
  if (c.size() == meshes.size()) out.colors = torch::cat(c);
  return out;
}

torch::Tensor RotationMatrix(const torch::Tensor& w) {
  // theta is kept away from zero so that sin(theta)/theta and its gradient stay finite.
  const auto theta2 = (w * w).sum() + 1e-10;
  const auto theta = torch::sqrt(theta2);
  const auto k = Skew(w);
  return torch::eye(3, kDouble) + torch::sin(theta) / theta * k +
         (1 - torch::cos(theta)) / theta2 * torch::matmul(k, k);
}

CameraTensor ToTensor(const core::Pose& pose) {
  const Eigen::Matrix3d r = pose.rotation.toRotationMatrix();
  auto rotation = torch::empty({3, 3}, kDouble);
  auto translation = torch::empty({3}, kDouble);
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) rotation[i][j] = r(i, j);
    translation[i] = pose.translation[i];
  }
  return {rotation, translation};
}

core::Pose ToPose(const CameraTensor& camera) {
  const auto r = camera.rotation.detach().contiguous();
  const auto t = camera.translation.detach().contiguous();
  Eigen::Matrix3d m;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) m(i, j) = r[i][j].item<double>();
  core::Pose pose;
  pose.rotation = core::Quat(m).normalized();
  for (int i = 0; i < 3; ++i) pose.translation[i] = t[i].item<double>();
  return pose;
}

CameraTensor PerturbPose(const core::Pose& pose, const torch::Tensor& delta) {
  const CameraTensor base = ToTensor(pose);
  const auto dr = RotationMatrix(delta.slice(0, 0, 3));
  return {torch::matmul(base.rotation, dr),
          torch::matmul(base.rotation, delta.slice(0, 3, 6)) + base.translation};
}

core::Pose ApplyDelta(const core::Pose& pose, const torch::Tensor& delta) {
  torch::NoGradGuard no_grad;
  return ToPose(PerturbPose(pose, delta.detach()));
}

SoftImage SoftRasterize(const RasterMesh& mesh, const core::PinholeIntrinsics& k,
                        const CameraTensor& camera, const SoftRasterOptions& options) {
  const int64_t pixel_count = static_cast<int64_t>(k.width) * k.height;
  // Base -> camera: p_c = R^T (p - t); then the pinhole projection.
  const auto local = torch::matmul(mesh.vertices - camera.translation, camera.rotation);
  const auto z = local.select(1, 2);
  const auto u = k.fx * local.select(1, 0) / z + k.cx;
  const auto v = k.fy * local.select(1, 1) / z + k.cy;

  std::vector<int64_t> pixels, triangles;
  {
    torch::NoGradGuard no_grad;
    FindPairs(u.detach().contiguous(), v.detach().contiguous(), z.detach().contiguous(),
              mesh.faces.contiguous(), k, options, pixels, triangles);
  }
  SoftImage image;
  if (pixels.empty()) {
    image.silhouette = torch::zeros({k.height, k.width}, kDouble) + 0 * u.sum();
    image.depth = torch::zeros({k.height, k.width}, kDouble) + 0 * u.sum();
    if (mesh.colors.defined())
      image.rgb = torch::zeros({k.height, k.width, 3}, kDouble) + 0 * mesh.colors.sum();
    return image;
  }
  const auto pixel =
      torch::from_blob(pixels.data(), {static_cast<int64_t>(pixels.size())}, kLong).clone();
  const auto tri =
      torch::from_blob(triangles.data(), {static_cast<int64_t>(triangles.size())}, kLong).clone();
  const auto px = torch::remainder(pixel, k.width).to(torch::kFloat64);
  const auto py = torch::div(pixel, k.width, "floor").to(torch::kFloat64);
  const auto corners = mesh.faces.index_select(0, tri);  // [P, 3]
  torch::Tensor cu[3], cv[3], cz[3];
  for (int i = 0; i < 3; ++i) {
    const auto index = corners.select(1, i);
    cu[i] = u.index_select(0, index);
    cv[i] = v.index_select(0, index);
    cz[i] = z.index_select(0, index);
  }
  // Edge functions: e_i is twice the area of (corner i+1, corner i+2, pixel).
  auto edge = [&](int a, int b) {
    return (cu[b] - cu[a]) * (py - cv[a]) - (cv[b] - cv[a]) * (px - cu[a]);
  };
  auto length = [&](int a, int b) {
    return torch::sqrt((cu[b] - cu[a]).square() + (cv[b] - cv[a]).square() + 1e-12);
  };
  const auto e01 = edge(0, 1), e12 = edge(1, 2), e20 = edge(2, 0);
  const auto area2 = e01 + e12 + e20;
  const auto sign = torch::sign(area2.detach());
  const auto distance = torch::min(torch::min(sign * e01 / length(0, 1), sign * e12 / length(1, 2)),
                                   sign * e20 / length(2, 0));
  const auto scaled = distance / options.sigma;
  const auto coverage = torch::sigmoid(scaled);

  // Screen-space barycentrics, clamped to the triangle for pixels just outside it; then
  // perspective-correct depth and colour.
  auto w0 = (e12 / area2).clamp(0, 1), w1 = (e20 / area2).clamp(0, 1),
       w2 = (e01 / area2).clamp(0, 1);
  const auto wsum = w0 + w1 + w2 + 1e-12;
  w0 = w0 / wsum;
  w1 = w1 / wsum;
  w2 = w2 / wsum;
  const auto inverse_depth = w0 / cz[0] + w1 / cz[1] + w2 / cz[2];
  const auto depth = 1 / inverse_depth;

  // Silhouette: 1 - prod(1 - p), as a sum of logs.
  const auto log_miss = torch::log1p(-coverage.clamp_max(1 - 1e-12));
  const auto sum_log_miss = torch::zeros({pixel_count}, kDouble).index_add(0, pixel, log_miss);
  image.silhouette = (1 - torch::exp(sum_log_miss)).reshape({k.height, k.width});

  // Soft z-buffer: softmax over the pixel's triangles of log p - z / gamma, shifted by the
  // pixel's largest logit (found without gradients) for stability.
  const auto logit = torch::log_sigmoid(scaled) - depth / options.gamma;
  torch::Tensor shift;
  {
    torch::NoGradGuard no_grad;
    std::vector<double> best(pixel_count, -std::numeric_limits<double>::infinity());
    const auto l = logit.detach().contiguous();
    const double* lp = l.data_ptr<double>();
    for (size_t i = 0; i < pixels.size(); ++i) best[pixels[i]] = std::max(best[pixels[i]], lp[i]);
    for (double& b : best)
      if (!std::isfinite(b)) b = 0;
    shift = torch::from_blob(best.data(), {pixel_count}, kDouble).clone().index_select(0, pixel);
  }
  const auto weight = torch::exp(logit - shift);
  const auto total = torch::zeros({pixel_count}, kDouble).index_add(0, pixel, weight);
  const auto denominator = total + (total.detach() <= 0).to(torch::kFloat64);
  image.depth =
      (torch::zeros({pixel_count}, kDouble).index_add(0, pixel, weight * depth) / denominator)
          .reshape({k.height, k.width});
  if (mesh.colors.defined()) {
    torch::Tensor color = torch::zeros({static_cast<int64_t>(pixels.size()), 3}, kDouble);
    for (int i = 0; i < 3; ++i) {
      const auto c = mesh.colors.index_select(0, corners.select(1, i));
      color = color + c * ((i == 0 ? w0 : i == 1 ? w1 : w2) / cz[i]).unsqueeze(1);
    }
    color = color * depth.unsqueeze(1);
    image.rgb =
        (torch::zeros({pixel_count, 3}, kDouble).index_add(0, pixel, weight.unsqueeze(1) * color) /
         denominator.unsqueeze(1))
            .reshape({k.height, k.width, 3});
  }
  return image;
}

core::Image BeforeAfterPicture(const torch::Tensor& rgb, const torch::Tensor& depth,
                               const SoftImage& before, const SoftImage& after, double outlier) {
  torch::NoGradGuard no_grad;
  const int h = static_cast<int>(depth.size(0)), w = static_cast<int>(depth.size(1));
  core::Image image{5 * w, h, 3, 8, std::vector<uint8_t>(5 * static_cast<size_t>(w) * h * 3)};
  auto put = [&](int panel, const torch::Tensor& colour) {
    const auto a = colour.contiguous().clamp(0, 1);
    const auto acc = a.accessor<double, 3>();
    for (int r = 0; r < h; ++r)
      for (int c = 0; c < w; ++c)
        for (int k = 0; k < 3; ++k)
          image.bytes[(static_cast<size_t>(r) * 5 * w + panel * w + c) * 3 + k] =
              static_cast<uint8_t>(acc[r][c][k] * 255 + 0.5);
  };
  put(0, rgb);
  int panel = 1;
  for (const SoftImage* s : {&before, &after}) put(panel++, s->rgb * s->silhouette.unsqueeze(2));
  for (const SoftImage* s : {&before, &after}) {
    const auto both = ((depth > 0) & (s->silhouette > 0.5)).to(torch::kFloat64);
    const auto error = ((s->depth - depth).abs() / outlier).clamp(0, 1) * both;
    put(panel++, error.unsqueeze(2).expand({h, w, 3}));
  }
  return image;
}

}  // namespace twinforge::real2sim
