// A differentiable renderer on LibTorch autograd: soft rasterization of triangle meshes (as in
// SoftRas, Liu et al. 2019) into silhouette, depth and colour images for a pinhole camera, on the
// CPU, in double precision.
//
// Every triangle covers a pixel with probability sigmoid(d / sigma), d the signed distance in
// pixels from the pixel centre to the triangle's projected edges (positive inside). The
// silhouette is 1 - prod(1 - p) over the triangles near the pixel; depth and colour blend the
// triangles' perspective-correct values with weights p * exp(-z / gamma) (a soft z-buffer:
// nearer surfaces win, ties share). Gradients reach the vertices, the vertex colours and the
// camera pose through all three images.
//
// Only (pixel, triangle) pairs within `cutoff` sigmas of a triangle are formed, found without
// gradients first, so a frame costs O(pixels covered), not O(pixels x triangles).
//
// Includes <torch/torch.h>: include it only from the calibrate module's .cpp files and tests.
#pragma once

#include <torch/torch.h>

#include <vector>

#include "core/image.h"
#include "core/pinhole.h"
#include "core/se3.h"

namespace twinforge::real2sim {

struct SoftRasterOptions {
  double sigma = 0.7;    // px, the width of a triangle's soft edge
  double gamma = 0.004;  // m, the soft z-buffer's depth temperature
  double cutoff = 6;     // sigmas beyond an edge at which a triangle stops counting
  double near = 0.02;    // m, triangles with a vertex nearer than this are left out
};

// A triangle mesh to render, in the robot base frame.
struct RasterMesh {
  torch::Tensor vertices;  // [V, 3] double, m
  torch::Tensor faces;     // [F, 3] int64
  torch::Tensor colors;    // [V, 3] double in [0, 1] (may be undefined: no colour image)
};

struct SoftImage {
  torch::Tensor silhouette;  // [H, W] in [0, 1]
  torch::Tensor depth;       // [H, W] m along the optical axis, 0 where no triangle is near
  torch::Tensor rgb;         // [H, W, 3] (undefined without colours)
};

// A camera pose as tensors: camera (OpenCV axes) -> base rotation [3, 3] and translation [3].
struct CameraTensor {
  torch::Tensor rotation, translation;
};

// Renders `mesh` as seen by a camera with `intrinsics` at `camera` (camera -> base).
SoftImage SoftRasterize(const RasterMesh& mesh, const core::PinholeIntrinsics& intrinsics,
                        const CameraTensor& camera, const SoftRasterOptions& options = {});

// An axis-aligned box of `size` at `center` in one colour (12 triangles, outward), and meshes
// joined into one.
RasterMesh BoxMesh(const Eigen::Vector3d& center, const Eigen::Vector3d& size,
                   const Eigen::Vector3d& color);
RasterMesh JoinMeshes(const std::vector<RasterMesh>& meshes);

// Rotation matrix [3, 3] of a rotation vector [3] (Rodrigues), differentiable at zero.
torch::Tensor RotationMatrix(const torch::Tensor& rotation_vector);
// A pose perturbed by a 6-vector (rotation vector, translation) in its own frame:
// pose * (Exp(delta[0:3]), delta[3:6]), as tensors. `delta` is [6] double.
CameraTensor PerturbPose(const core::Pose& pose, const torch::Tensor& delta);
// The same, evaluated: a pose composed with the correction `delta`.
core::Pose ApplyDelta(const core::Pose& pose, const torch::Tensor& delta);
// A frame against the twin rendered two ways (before and after a refinement), as one picture of
// five panels: the real colour | the first render | the second | the depth error of each (black:
// agree; white: `outlier` m or more off; where both have a surface). rgb [H, W, 3], depth [H, W].
core::Image BeforeAfterPicture(const torch::Tensor& rgb, const torch::Tensor& depth,
                               const SoftImage& before, const SoftImage& after, double outlier);

// [3, 3] / [3] double tensors of a pose, and back.
CameraTensor ToTensor(const core::Pose& pose);
core::Pose ToPose(const CameraTensor& camera);

}  // namespace twinforge::real2sim
