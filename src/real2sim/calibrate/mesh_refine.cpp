#include "real2sim/calibrate/mesh_refine.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <set>
#include <utility>

#include "core/config.h"
#include "core/error.h"
#include "core/fs.h"
#include "core/image.h"
#include "real2sim/calibrate/twin_geometry.h"
#include "real2sim/export.h"
#include "real2sim/fusion.h"
#include "real2sim/recipe.h"
#include "real2sim/twin_edit.h"
#include "real2sim/twin_spec.h"
#include "sim/camera.h"

namespace twinforge::real2sim {
namespace {

const auto kDouble = torch::TensorOptions().dtype(torch::kFloat64);
const auto kLong = torch::TensorOptions().dtype(torch::kInt64);

torch::Tensor Rows(const std::vector<Eigen::Vector3d>& points) {
  auto t = torch::empty({static_cast<int64_t>(points.size()), 3}, kDouble);
  auto a = t.accessor<double, 2>();
  for (size_t i = 0; i < points.size(); ++i)
    for (int k = 0; k < 3; ++k) a[i][k] = points[i][k];
  return t;
}

// The meshes as one: vertices, normals, colours and faces, and each mesh edge once.
struct Packed {
  torch::Tensor vertices, normals, colors, faces, edges;
  std::vector<int64_t> first;  // each mesh's first vertex
  // Each mesh's centroid (the mean of its vertices) and the rms distance of its vertices from
  // the upright line through it, m.
  std::vector<Eigen::Vector3d> centroid;
  std::vector<double> radius;
};

Packed Pack(const std::vector<Mesh>& meshes) {
  std::vector<Eigen::Vector3d> v, n, c;
  std::vector<int64_t> f;
  std::set<std::pair<int64_t, int64_t>> edges;
  Packed p;
  for (const Mesh& mesh : meshes) {
    const int64_t first = static_cast<int64_t>(v.size());
    p.first.push_back(first);
    const auto normals = VertexNormals(mesh);
    v.insert(v.end(), mesh.vertices.begin(), mesh.vertices.end());
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    for (const auto& x : mesh.vertices) centroid += x;
    centroid /= std::max<size_t>(1, mesh.vertices.size());
    double spread = 0;
    for (const auto& x : mesh.vertices) spread += (x - centroid).head<2>().squaredNorm();
    p.centroid.push_back(centroid);
    p.radius.push_back(std::sqrt(spread / std::max<size_t>(1, mesh.vertices.size())));
    n.insert(n.end(), normals.begin(), normals.end());
    for (size_t i = 0; i < mesh.vertices.size(); ++i)
      c.push_back(mesh.colors.size() == mesh.vertices.size() ? mesh.colors[i]
                                                             : Eigen::Vector3d::Constant(0.5));
    for (const auto& t : mesh.triangles) {
      for (int k = 0; k < 3; ++k) {
        f.push_back(first + t[k]);
        const int64_t a = first + t[k], b = first + t[(k + 1) % 3];
        edges.emplace(std::min(a, b), std::max(a, b));
      }
    }
  }
  p.first.push_back(static_cast<int64_t>(v.size()));
  p.vertices = Rows(v);
  p.normals = Rows(n);
  p.colors = Rows(c);
  p.faces = torch::from_blob(f.data(), {static_cast<int64_t>(f.size() / 3), 3}, kLong).clone();
  std::vector<int64_t> e;
  for (const auto& [a, b] : edges) e.insert(e.end(), {a, b});
  p.edges = torch::from_blob(e.data(), {static_cast<int64_t>(edges.size()), 2}, kLong).clone();
  return p;
}

// The vertices with those from `from` on raised by `lift` (m, a scalar tensor).
torch::Tensor Lifted(const torch::Tensor& vertices, int64_t from, const torch::Tensor& lift) {
  auto up = torch::zeros_like(vertices);
  up.slice(0, from).select(1, 2).fill_(1);
  return vertices + up * lift;
}

// The refined meshes and what else a view shows, as one mesh to render; with `lift` (m), the
// table raised by it.
RasterMesh Scene(const RasterMesh& refined, const RefineView& view,
                 const torch::Tensor& lift = {}) {
  if (!view.fixed.vertices.defined()) return refined;
  RasterMesh fixed = view.fixed;
  if (!fixed.colors.defined()) fixed.colors = torch::zeros({fixed.vertices.size(0), 3}, kDouble);
  if (lift.defined() && view.table_from >= 0)
    fixed.vertices = Lifted(fixed.vertices, view.table_from, lift);
  return JoinMeshes({refined, fixed});
}

torch::Tensor Huber(const torch::Tensor& r, double delta) {
  const auto a = r.abs();
  return torch::where(a < delta, 0.5 * a.square(), delta * (a - 0.5 * delta));
}

// Per view, the pixels where the refined meshes are what the camera sees (not their edges, not
// what else the view shows) and the real camera returned something.
std::vector<torch::Tensor> Ownership(const Packed& p, const std::vector<RefineView>& views,
                                     const SoftRasterOptions& raster) {
  torch::NoGradGuard no_grad;
  const RasterMesh marked{p.vertices, p.faces, torch::ones_like(p.vertices)};
  std::vector<torch::Tensor> owned;
  for (const RefineView& view : views) {
    const SoftImage image =
        SoftRasterize(Scene(marked, view), view.intrinsics, ToTensor(view.camera_to_base), raster);
    owned.push_back((image.rgb.select(2, 0) > 0.99) & (image.silhouette > 0.99) & (view.depth > 0));
  }
  return owned;
}

// Per view, which of the meshes each owned pixel shows (-1: none of them, or more than one):
// each mesh is rendered in its own shade of red.
std::vector<torch::Tensor> MeshIds(const Packed& p, const std::vector<RefineView>& views,
                                   const std::vector<torch::Tensor>& owned,
                                   const SoftRasterOptions& raster) {
  torch::NoGradGuard no_grad;
  const int64_t count = static_cast<int64_t>(p.first.size()) - 1;
  auto shade = torch::zeros_like(p.vertices);
  for (int64_t m = 0; m < count; ++m)
    shade.slice(0, p.first[m], p.first[m + 1]).fill_(static_cast<double>(m + 1) / count);
  const RasterMesh marked{p.vertices, p.faces, shade};
  std::vector<torch::Tensor> ids;
  for (size_t i = 0; i < views.size(); ++i) {
    const SoftImage image = SoftRasterize(Scene(marked, views[i]), views[i].intrinsics,
                                          ToTensor(views[i].camera_to_base), raster);
    const auto code = image.rgb.select(2, 0) * count;
    const auto id = torch::round(code) - 1;
    // Within 1% of a shade, as Ownership asks of the one shade.
    const auto pure = (code - torch::round(code)).abs() < 0.01 * torch::round(code);
    ids.push_back(torch::where(owned[i] & pure, id, torch::full_like(id, -1)).to(torch::kInt64));
  }
  return ids;
}

// Per mesh, the mean absolute depth error (mm) over the pixels `ids` gives it that agree within
// the outlier distance, with the meshes at `vertices` seen from the views' own poses.
std::vector<double> MeshDepthErrors(const Packed& p, const torch::Tensor& vertices,
                                    const std::vector<RefineView>& views,
                                    const std::vector<torch::Tensor>& ids,
                                    const MeshRefineOptions& o, const SoftRasterOptions& raster) {
  torch::NoGradGuard no_grad;
  const size_t count = p.first.size() - 1;
  std::vector<double> sum(count, 0), n(count, 0);
  const RasterMesh refined{vertices, p.faces, p.colors};
  for (size_t i = 0; i < views.size(); ++i) {
    const SoftImage image = SoftRasterize(Scene(refined, views[i]), views[i].intrinsics,
                                          ToTensor(views[i].camera_to_base), raster);
    const auto r = ((image.depth - views[i].depth) * 1000).abs();
    for (size_t m = 0; m < count; ++m) {
      const auto in = (ids[i] == static_cast<int64_t>(m)) & (r < o.outlier);
      sum[m] += r.masked_select(in).sum().item<double>();
      n[m] += in.sum().item<double>();
    }
  }
  std::vector<double> error(count, 0);
  for (size_t m = 0; m < count; ++m)
    if (n[m] > 0) error[m] = sum[m] / n[m];
  return error;
}

// A camera pose turned about its own centre by delta[0:3] (rotation vector) and moved by
// delta[3:6], both in the base frame (rad, m): a correction common to all views is then the
// same numbers in each.
CameraTensor Corrected(const core::Pose& pose, const torch::Tensor& delta) {
  const CameraTensor base = ToTensor(pose);
  return {torch::matmul(RotationMatrix(delta.slice(0, 0, 3)), base.rotation),
          base.translation + delta.slice(0, 3, 6)};
}

struct Agreement {
  double depth_mm = 0, rgb = 0, inliers = 0;
};

// How well the meshes at `vertices` with `colors` explain the views seen from `poses`, over the
// owned pixels.
Agreement Agree(const Packed& p, const torch::Tensor& vertices, const torch::Tensor& colors,
                const std::vector<RefineView>& views, const std::vector<core::Pose>& poses,
                const std::vector<torch::Tensor>& owned, const MeshRefineOptions& o,
                const SoftRasterOptions& raster) {
  torch::NoGradGuard no_grad;
  double depth = 0, rgb = 0;
  int64_t inliers = 0, pixels = 0;
  const RasterMesh refined{vertices, p.faces, colors};
  for (size_t i = 0; i < views.size(); ++i) {
    const SoftImage image =
        SoftRasterize(Scene(refined, views[i]), views[i].intrinsics, ToTensor(poses[i]), raster);
    const auto r = ((image.depth - views[i].depth) * 1000).abs();
    const auto in = owned[i] & (r < o.outlier);
    depth += r.masked_select(in).sum().item<double>();
    rgb += (image.rgb - views[i].rgb).abs().mean(2).masked_select(in).sum().item<double>();
    inliers += in.sum().item<int64_t>();
    pixels += owned[i].sum().item<int64_t>();
  }
  Agreement a;
  if (inliers > 0) a.depth_mm = depth / inliers, a.rgb = rgb / inliers;
  if (pixels > 0) a.inliers = static_cast<double>(inliers) / pixels;
  return a;
}

// The objects PlaceObjects places, one per mesh file: the solids of its parts where they all
// collide as solids and show the object as the mesh does (what the physics holds and inserts:
// a peg's box, its hole's walls), else the refined mesh. Solids show the object when at least
// 90% of the mesh's vertices lie within 3 mm of them: a mug's cylinder lacks the handle and the
// cavity the frames see, and placed by them the mug ended farther from the real one.
std::vector<Mesh> ObjectsOf(const TwinSpec& spec, const std::vector<std::string>& files,
                            const std::vector<Mesh>& refined) {
  std::vector<Mesh> objects;
  for (size_t i = 0; i < files.size(); ++i) {
    Mesh solids;
    bool all = true;
    for (const auto& part : spec.parts) {
      if (part.mesh != files[i]) continue;
      all = all && part.collision == PartSpec::Collision::kSolids;
      for (const auto& box : part.boxes) AppendMesh(solids, BoxMesh(box));
    }
    double near = 0;
    if (all)
      for (const double d : SurfaceDistances(refined[i].vertices, solids)) near += d < 0.003;
    const double share = all ? near / std::max<size_t>(1, refined[i].vertices.size()) : 0;
    if (all)
      spdlog::info("object placement: {}: {:.0f}% of the mesh within 3 mm of its solids", files[i],
                   100 * share);
    objects.push_back(share >= 0.9 ? solids : refined[i]);
  }
  return objects;
}

}  // namespace

std::vector<Eigen::Vector3d> VertexNormals(const Mesh& mesh) {
  std::vector<Eigen::Vector3d> n(mesh.vertices.size(), Eigen::Vector3d::Zero());
  for (const auto& t : mesh.triangles) {
    // The cross product's length is twice the area: an area-weighted sum.
    const Eigen::Vector3d a = mesh.vertices[t[1]] - mesh.vertices[t[0]];
    const Eigen::Vector3d b = mesh.vertices[t[2]] - mesh.vertices[t[0]];
    const Eigen::Vector3d face = a.cross(b);
    for (int k = 0; k < 3; ++k) n[t[k]] += face;
  }
  for (auto& v : n)
    if (v.norm() > 1e-15) v.normalize();
  return n;
}

RefineView ReduceFrame(const core::PinholeIntrinsics& k, const core::Pose& camera_to_base,
                       const std::vector<float>& depth_m, const std::vector<uint8_t>& rgb,
                       int factor) {
  if (factor < 1) throw core::Error("ReduceFrame: factor must be at least 1");
  const size_t pixels = static_cast<size_t>(k.width) * k.height;
  if (depth_m.size() != pixels || rgb.size() != 3 * pixels)
    throw core::Error("ReduceFrame: the images are not " + std::to_string(k.width) + "x" +
                      std::to_string(k.height));
  RefineView view;
  view.camera_to_base = camera_to_base;
  view.intrinsics = k;
  view.intrinsics.width = k.width / factor;
  view.intrinsics.height = k.height / factor;
  view.intrinsics.fx = k.fx / factor;
  view.intrinsics.fy = k.fy / factor;
  // Pixel centres: a reduced pixel (c) covers full pixels factor*c .. factor*c + factor - 1.
  view.intrinsics.cx = (k.cx + 0.5) / factor - 0.5;
  view.intrinsics.cy = (k.cy + 0.5) / factor - 0.5;
  const int w = view.intrinsics.width, h = view.intrinsics.height;
  view.depth = torch::zeros({h, w}, kDouble);
  view.rgb = torch::zeros({h, w, 3}, kDouble);
  auto da = view.depth.accessor<double, 2>();
  auto ca = view.rgb.accessor<double, 3>();
  std::vector<float> block;
  for (int r = 0; r < h; ++r) {
    for (int c = 0; c < w; ++c) {
      block.clear();
      double sum[3] = {0, 0, 0};
      for (int dr = 0; dr < factor; ++dr) {
        for (int dc = 0; dc < factor; ++dc) {
          const size_t i = static_cast<size_t>(r * factor + dr) * k.width + (c * factor + dc);
          if (depth_m[i] > 0 && std::isfinite(depth_m[i])) block.push_back(depth_m[i]);
          for (int j = 0; j < 3; ++j) sum[j] += rgb[3 * i + j];
        }
      }
      for (int j = 0; j < 3; ++j) ca[r][c][j] = sum[j] / (255.0 * factor * factor);
      if (2 * block.size() < static_cast<size_t>(factor * factor)) continue;
      std::nth_element(block.begin(), block.begin() + block.size() / 2, block.end());
      da[r][c] = block[block.size() / 2];
    }
  }
  return view;
}

nlohmann::json MeshRefinement::ToJson() const {
  nlohmann::json frames = nlohmann::json::array();
  for (const auto& c : frame_corrections)
    frames.push_back({{"translation_mm", 1000 * c.translation.norm()},
                      {"rotation_deg", Eigen::AngleAxisd(c.rotation).angle() * 180 / M_PI}});
  nlohmann::json objects = nlohmann::json::array();
  for (size_t i = 0; i < object_corrections.size(); ++i) {
    const core::Pose& c = object_corrections[i];
    const Eigen::Vector3d& at = object_centroids[i];
    objects.push_back({{"translation_mm", 1000 * (c * at - at).norm()},
                       {"rotation_deg", Eigen::AngleAxisd(c.rotation).angle() * 180 / M_PI},
                       {"depth_error_mm",
                        {{"before", object_errors_before[i]}, {"placed", object_errors_after[i]}}},
                       {"placed", static_cast<bool>(object_placed[i])}});
  }
  return {{"frame_corrections", frames},
          {"table_lift_mm", table_lift_mm},
          {"object_corrections", objects},
          {"depth_error_mm", {{"before", depth_error_before}, {"after", depth_error_after}}},
          {"rgb_error", {{"before", rgb_error_before}, {"after", rgb_error_after}}},
          {"inliers", {{"before", inliers_before}, {"after", inliers_after}}},
          {"offset_rms_mm", offset_rms},
          {"offset_max_mm", offset_max},
          {"loss", loss},
          {"seconds", seconds}};
}

std::vector<RefineView> LiftTable(const std::vector<RefineView>& views, double lift) {
  std::vector<RefineView> lifted = views;
  if (lift == 0) return lifted;
  torch::NoGradGuard no_grad;
  for (auto& v : lifted)
    if (v.fixed.vertices.defined() && v.table_from >= 0)
      v.fixed.vertices = Lifted(v.fixed.vertices, v.table_from, torch::tensor(lift, kDouble));
  return lifted;
}

namespace {

// RefineMeshes (the offsets, the colours and, with o.frame_poses, the frames' poses), or with
// `place` PlaceObjects (the objects' poses alone).
MeshRefinement Refine(const std::vector<Mesh>& meshes, const std::vector<RefineView>& views,
                      const MeshRefineOptions& o, bool place, core::Progress* progress) {
  const bool shape = !place, frame_poses = o.frame_poses && !place;
  const auto start = std::chrono::steady_clock::now();
  const Packed p = Pack(meshes);
  SoftRasterOptions raster;
  raster.sigma = o.sigma;
  const std::vector<torch::Tensor> owned = Ownership(p, views, raster);
  std::vector<size_t> seen;  // the views that show the meshes
  for (size_t i = 0; i < views.size(); ++i)
    if (owned[i].any().item<bool>()) seen.push_back(i);
  if (seen.empty())
    throw core::ConfigError("mesh refinement", "frames",
                            "frames that show the twin's scanned meshes (none of " +
                                std::to_string(views.size()) + " does)");

  const int64_t vertex_count = p.vertices.size(0);
  const int64_t mesh_count = static_cast<int64_t>(meshes.size());
  auto offsets = torch::zeros({vertex_count}, kDouble).requires_grad_(shape);  // mm
  auto colors = p.colors.clone().requires_grad_(shape);
  // Each mesh's motion on the table: a turn about the upright through its centroid (the angle
  // times the mesh's rms radius about it, mm) and a shift along x and y (mm), base frame. What
  // stands on the table neither tilts nor sinks; a 6-dof motion tilted the peg's block 1 deg and
  // put the peg's tip under the table.
  auto motions = torch::zeros({mesh_count, 3}, kDouble);
  if (place) motions.requires_grad_(true);
  const auto zeros = torch::zeros({2}, kDouble), zero = torch::zeros({1}, kDouble);
  auto turn = [&](const torch::Tensor& m, size_t i) {
    return RotationMatrix(
        torch::cat({zeros, m[i].slice(0, 0, 1) * (1e-3 / std::max(p.radius[i], 1e-6))}));
  };
  auto shift = [&](const torch::Tensor& m, size_t i) {
    return torch::cat({m[i].slice(0, 1, 3), zero}) * 1e-3;
  };
  auto posed = [&](const torch::Tensor& mm, const torch::Tensor& m) {
    const auto offset = p.vertices + p.normals * (mm * 1e-3).unsqueeze(1);
    if (!place) return offset;
    std::vector<torch::Tensor> moved;
    for (size_t i = 0; i < meshes.size(); ++i) {
      const auto c =
          torch::tensor({p.centroid[i].x(), p.centroid[i].y(), p.centroid[i].z()}, kDouble);
      const auto local = offset.slice(0, p.first[i], p.first[i + 1]) - c;
      moved.push_back(torch::matmul(local, turn(m, i).transpose(0, 1)) + c + shift(m, i));
    }
    return torch::cat(moved);
  };

  // Each frame's pose correction (rotation vector in mrad, translation in mm, Corrected): a
  // hand camera's reported pose is a few mm off, differently in every frame. The corrections
  // are taken about their mean: the errors are the arm's, not a bias, and a shift shared by every
  // frame would move the meshes with it wherever the table and the arm do not pin it down.
  auto free = torch::zeros({static_cast<int64_t>(views.size()), 6}, kDouble);
  if (frame_poses) free.requires_grad_(true);
  auto centred = [&] { return free - free.mean(0, true); };
  auto corrected = [&](const torch::Tensor& c) {
    std::vector<core::Pose> poses;
    for (size_t i = 0; i < views.size(); ++i)
      poses.push_back(ToPose(Corrected(views[i].camera_to_base, c[i].detach() * 1e-3)));
    return poses;
  };

  MeshRefinement result;
  const Agreement before =
      Agree(p, p.vertices, p.colors, views, corrected(free.detach()), owned, o, raster);
  // Offsets, colours, frame poses and object poses step at their own rates: one group each.
  std::vector<torch::optim::OptimizerParamGroup> groups;
  const double rates[] = {o.learning_rate, o.color_learning_rate, o.pose_learning_rate,
                          o.object_pose_learning_rate};
  // The table's height (mm) steps with the frames' poses.
  auto lift = torch::zeros({}, kDouble);
  if (frame_poses && o.table_height) lift.requires_grad_(true);
  const std::vector<torch::Tensor> tensors[] = {{offsets}, {colors}, {free, lift}, {motions}};
  for (int g = 0; g < 4; ++g)
    groups.emplace_back(tensors[g], std::make_unique<torch::optim::AdamOptions>(rates[g]));
  torch::optim::Adam adam(groups, torch::optim::AdamOptions(o.learning_rate));

  const int batch = std::min<int>(o.frames_per_step, static_cast<int>(seen.size()));
  for (int step = 0; step < o.iterations; ++step) {
    // Cosine decay to a tenth: large moves first, then settle.
    const double decay = 0.1 + 0.45 * (1 + std::cos(M_PI * step / std::max(1, o.iterations)));
    for (int g = 0; g < 4; ++g)
      static_cast<torch::optim::AdamOptions&>(adam.param_groups()[g].options())
          .lr(rates[g] * decay);
    adam.zero_grad();
    const RasterMesh refined{posed(offsets, motions), p.faces, colors};
    const auto corrections = centred();
    auto data = torch::zeros({}, kDouble);
    for (int b = 0; b < batch; ++b) {
      const size_t i = seen[(static_cast<size_t>(step) * batch + b) % seen.size()];
      const RefineView& view = views[i];
      const CameraTensor camera = frame_poses
                                      ? Corrected(view.camera_to_base, corrections[i] * 1e-3)
                                      : ToTensor(view.camera_to_base);
      const SoftImage image =
          SoftRasterize(Scene(refined, view, lift * 1e-3), view.intrinsics, camera, raster);
      const auto r = (image.depth - view.depth) * 1000;
      const auto close = r.detach().abs() < o.outlier;
      const auto in = owned[i] & close;
      if (frame_poses) {
        // What else the frame shows places its camera too (the table, the arm: known shapes).
        const auto rest = ~owned[i] & close & (view.depth > 0) & (image.silhouette.detach() > 0.99);
        if (rest.any().item<bool>()) data = data + Huber(r.masked_select(rest), o.huber).mean();
      }
      if (!in.any().item<bool>()) continue;
      data = data + Huber(r.masked_select(in), o.huber).mean();
      if (o.rgb_weight > 0 && shape)
        data = data + o.rgb_weight * (image.rgb - view.rgb).abs().mean(2).masked_select(in).mean();
    }
    auto loss = data / batch;
    if (p.edges.size(0) > 0)
      loss = loss + o.smoothness * (offsets.index_select(0, p.edges.select(1, 0)) -
                                    offsets.index_select(0, p.edges.select(1, 1)))
                                       .square()
                                       .mean();
    loss = loss + o.prior * offsets.square().mean();
    if (frame_poses) loss = loss + o.pose_prior * (corrections.square().mean() + lift.square());
    if (place) loss = loss + o.object_pose_prior * motions.square().mean();
    loss.backward();
    adam.step();
    {
      torch::NoGradGuard no_grad;
      offsets.clamp_(-o.max_offset, o.max_offset);
      colors.clamp_(0, 1);
    }
    result.loss.push_back(loss.item<double>());
    if (progress) progress->Advance(1, "loss " + std::to_string(result.loss.back()));
  }

  torch::NoGradGuard no_grad;
  if (place) {
    // An object keeps its pose unless its placement explains its own pixels clearly better: a
    // move that buys less was not told by the frames.
    const auto ids = MeshIds(p, views, owned, raster);
    result.object_errors_before =
        MeshDepthErrors(p, posed(offsets, torch::zeros_like(motions)), views, ids, o, raster);
    result.object_errors_after = MeshDepthErrors(p, posed(offsets, motions), views, ids, o, raster);
    for (size_t m = 0; m < meshes.size(); ++m) {
      const bool placed = result.object_errors_after[m] <
                          (1 - o.object_pose_min_gain) * result.object_errors_before[m];
      if (!placed) motions[m].zero_();
      result.object_placed.push_back(placed);
    }
  }
  const auto vertices = posed(offsets, motions);
  const std::vector<core::Pose> poses = corrected(centred());
  result.table_lift_mm = lift.item<double>();
  const Agreement after = Agree(p, vertices, colors, LiftTable(views, result.table_lift_mm * 1e-3),
                                poses, owned, o, raster);
  for (size_t i = 0; i < views.size(); ++i)
    result.frame_corrections.push_back(views[i].camera_to_base.Inverse() * poses[i]);
  // x -> R (x - c) + c + t, as a pose.
  for (size_t i = 0; place && i < meshes.size(); ++i) {
    const CameraTensor motion{turn(motions, i), shift(motions, i)};
    core::Pose pose = ToPose(motion);
    pose.translation += p.centroid[i] - pose.rotation * p.centroid[i];
    result.object_corrections.push_back(pose);
    result.object_centroids.push_back(p.centroid[i]);
  }
  result.depth_error_before = before.depth_mm;
  result.depth_error_after = after.depth_mm;
  result.rgb_error_before = before.rgb;
  result.rgb_error_after = after.rgb;
  result.inliers_before = before.inliers;
  result.inliers_after = after.inliers;
  result.offset_rms = std::sqrt(offsets.square().mean().item<double>());
  result.offset_max = offsets.abs().max().item<double>();
  const auto va = vertices.accessor<double, 2>();
  const auto ca = colors.accessor<double, 2>();
  for (size_t m = 0; m < meshes.size(); ++m) {
    Mesh out = meshes[m];
    out.colors.resize(out.vertices.size());
    for (int64_t v = p.first[m]; v < p.first[m + 1]; ++v) {
      out.vertices[v - p.first[m]] = Eigen::Vector3d(va[v][0], va[v][1], va[v][2]);
      out.colors[v - p.first[m]] = Eigen::Vector3d(ca[v][0], ca[v][1], ca[v][2]);
    }
    result.meshes.push_back(std::move(out));
  }
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  for (size_t m = 0; m < result.object_placed.size(); ++m)
    spdlog::info("object placement: object {}: depth error {:.2f} -> {:.2f} mm, {}", m,
                 result.object_errors_before[m], result.object_errors_after[m],
                 result.object_placed[m] ? "placed" : "not placed (too little better)");
  if (place)
    spdlog::info("object placement: depth error {:.2f} -> {:.2f} mm, {:.0f} s",
                 result.depth_error_before, result.depth_error_after, result.seconds);
  else
    spdlog::info(
        "mesh refinement: depth error {:.2f} -> {:.2f} mm, colour {:.3f} -> {:.3f}, offsets rms "
        "{:.2f} mm (max {:.2f}), {:.0f} s",
        result.depth_error_before, result.depth_error_after, result.rgb_error_before,
        result.rgb_error_after, result.offset_rms, result.offset_max, result.seconds);
  return result;
}

}  // namespace

MeshRefinement RefineMeshes(const std::vector<Mesh>& meshes, const std::vector<RefineView>& views,
                            const MeshRefineOptions& options, core::Progress* progress) {
  return Refine(meshes, views, options, false, progress);
}

MeshRefinement PlaceObjects(const std::vector<Mesh>& objects, const std::vector<RefineView>& views,
                            const MeshRefineOptions& options, core::Progress* progress) {
  return Refine(objects, views, options, true, progress);
}

MeshRefinement RefineTwinMeshes(const std::filesystem::path& twin_dir, const core::Scan& scan,
                                const MeshRefineOptions& options, core::Progress* progress) {
  namespace fs = std::filesystem;
  TwinSpec spec = LoadTwinSpec(twin_dir / "twin.yaml");
  std::vector<std::string> files;  // each scanned mesh once (parts cut from one share it)
  for (const auto& part : spec.parts)
    if (!part.mesh.empty() && std::find(files.begin(), files.end(), part.mesh) == files.end())
      files.push_back(part.mesh);
  if (files.empty())
    throw core::ConfigError((twin_dir / "twin.yaml").string(), "parts",
                            "a part with a scanned mesh to refine");
  std::vector<Mesh> meshes;
  for (const auto& f : files) meshes.push_back(ReadMesh(twin_dir / f));

  // The frames, reduced, each with the arm as it was and the table: what else they show.
  TwinGeometry geometry(sim::LoadTaskSpec((twin_dir / "task.yaml").string()), 3000);
  const mjModel* m = geometry.model();
  const int mount = mj_name2id(m, mjOBJ_BODY, "robot_mount");
  const int table = mj_name2id(m, mjOBJ_GEOM, "table");
  auto arm = [&](int g) { return mount >= 0 && sim::InSubtree(m, m->geom_bodyid[g], mount); };
  auto is_table = [&](int g) { return g == table; };
  // The table does not move with the arm: posed once, at the first frame's joints.
  const RasterMesh under =
      scan.frames.empty() ? RasterMesh{}
                          : geometry.Posed(scan.frames.front().joint_positions,
                                           scan.frames.front().gripper_width, nullptr, is_table);
  std::vector<RefineView> views;
  for (const auto& frame : scan.frames) {
    const int factor = std::max(1, frame.intrinsics.width / options.width);
    const core::Image color = core::ReadPng(scan.dir / frame.color);
    if (color.width != frame.intrinsics.width || color.height != frame.intrinsics.height ||
        color.channels < 3 || color.bit_depth != 8)
      throw core::ConfigError((scan.dir / frame.color).string(), "color",
                              "an 8-bit RGB image of the frame's size");
    std::vector<uint8_t> rgb(3 * static_cast<size_t>(color.width) * color.height);
    for (size_t i = 0; i < rgb.size() / 3; ++i)
      for (int k = 0; k < 3; ++k) rgb[3 * i + k] = color.bytes[i * color.channels + k];
    RefineView view = ReduceFrame(frame.intrinsics, frame.camera_to_base,
                                  ReadDepthMetres(scan, frame), rgb, factor);
    const RasterMesh shown =
        geometry.Posed(frame.joint_positions, frame.gripper_width, nullptr, arm);
    view.fixed = JoinMeshes({shown, under});
    if (under.vertices.size(0) > 0) view.table_from = shown.vertices.size(0);
    views.push_back(std::move(view));
  }
  MeshRefinement result = RefineMeshes(meshes, views, options, progress);
  const std::vector<RefineView> lifted = LiftTable(views, result.table_lift_mm * 1e-3);

  // Then the objects, seen from where the frames were corrected to; each mesh moves with its
  // object, and so does what the spec places with it (cuts, solids, sites, joint).
  nlohmann::json placement;
  if (options.object_poses) {
    std::vector<RefineView> corrected = lifted;
    for (size_t i = 0; i < views.size(); ++i)
      corrected[i].camera_to_base = views[i].camera_to_base * result.frame_corrections[i];
    const MeshRefinement placed =
        PlaceObjects(ObjectsOf(spec, files, result.meshes), corrected, options);
    for (size_t i = 0; i < files.size(); ++i) {
      for (auto& v : result.meshes[i].vertices) v = placed.object_corrections[i] * v;
      MoveParts(spec, PartsOfMesh(spec, files[i]), placed.object_corrections[i]);
    }
    result.object_corrections = placed.object_corrections;
    result.object_centroids = placed.object_centroids;
    result.object_errors_before = placed.object_errors_before;
    result.object_errors_after = placed.object_errors_after;
    result.object_placed = placed.object_placed;
    placement = {{"depth_error_mm",
                  {{"before", placed.depth_error_before}, {"after", placed.depth_error_after}}},
                 {"seconds", placed.seconds}};
    SaveTwinSpec(twin_dir / "twin.yaml", spec);
  }
  for (size_t i = 0; i < files.size(); ++i) WriteMesh(twin_dir / files[i], result.meshes[i]);
  ExportOptions export_options;
  export_options.cameras = ReadSceneCameras(twin_dir / "scene.xml");
  ExportMjcf(spec, twin_dir, export_options);

  // Before/after pictures of every frame.
  const fs::path report = twin_dir / "calibration";
  core::EnsureDirectory(report);
  torch::NoGradGuard no_grad;
  SoftRasterOptions sharp;
  sharp.sigma = options.sigma;
  const Packed before = Pack(meshes), after = Pack(result.meshes);
  for (size_t i = 0; i < views.size(); ++i) {
    const RefineView& v = views[i];
    auto render = [&](const Packed& p, const RefineView& shown, const core::Pose& pose) {
      return SoftRasterize(Scene({p.vertices, p.faces, p.colors}, shown), v.intrinsics,
                           ToTensor(pose), sharp);
    };
    const core::Image image =
        BeforeAfterPicture(v.rgb, v.depth, render(before, v, v.camera_to_base),
                           render(after, lifted[i], v.camera_to_base * result.frame_corrections[i]),
                           options.outlier * 1e-3);
    char name[48];
    std::snprintf(name, sizeof(name), "mesh_%02zu.png", i);
    core::WritePng(report / name, image);
  }
  nlohmann::json json = result.ToJson();
  json["scan"] = scan.dir.string();
  json["meshes"] = files;
  json["options"] = core::ToJson(options);
  if (!placement.is_null()) json["placement"] = placement;
  core::WriteFileAtomic(report / "mesh.json", json.dump(2));
  return result;
}

}  // namespace twinforge::real2sim
