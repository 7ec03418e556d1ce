#include "sim/camera.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"
#include "sim/robot_mask.h"

namespace twinforge::sim {

namespace {

using RowMat3 = Eigen::Matrix<double, 3, 3, Eigen::RowMajor>;

// Uniform point on the surface of a unit primitive (sizes applied later), area-weighted over its
// parts for the given size.
Eigen::Vector3d SamplePrimitive(int type, const double* size, core::Rng& rng) {
  switch (type) {
    case mjGEOM_SPHERE: {
      Eigen::Vector3d v(rng.Normal(), rng.Normal(), rng.Normal());
      return v.normalized();
    }
    case mjGEOM_BOX: {
      const double ax = size[1] * size[2], ay = size[0] * size[2], az = size[0] * size[1];
      double pick = rng.Uniform(0, ax + ay + az);
      const int face_axis = pick < ax ? 0 : (pick < ax + ay ? 1 : 2);
      Eigen::Vector3d v(rng.Uniform(-1, 1), rng.Uniform(-1, 1), rng.Uniform(-1, 1));
      v[face_axis] = rng.Bernoulli(0.5) ? 1.0 : -1.0;
      return v;
    }
    case mjGEOM_CYLINDER:
    case mjGEOM_CAPSULE: {
      // Side (radius r, half-length h) versus caps (flat discs or hemispheres).
      const double r = size[0], h = size[1];
      const double side = 4 * M_PI * r * h;
      const double caps = type == mjGEOM_CYLINDER ? 2 * M_PI * r * r : 4 * M_PI * r * r;
      const double angle = rng.Uniform(0, 2 * M_PI);
      if (rng.Uniform(0, side + caps) < side)
        return {std::cos(angle), std::sin(angle), rng.Uniform(-1, 1)};
      const double sign = rng.Bernoulli(0.5) ? 1.0 : -1.0;
      if (type == mjGEOM_CYLINDER) {
        const double rho = std::sqrt(rng.Uniform());
        return {rho * std::cos(angle), rho * std::sin(angle), sign};
      }
      // Capsule cap: a hemisphere; x, y in radii, z in half-lengths plus radii (see Transform).
      Eigen::Vector3d v(rng.Normal(), rng.Normal(), std::abs(rng.Normal()));
      v.normalize();
      return {v.x(), v.y(), sign * (1.0 + v.z() * r / std::max(h, 1e-9))};
    }
    default:
      return Eigen::Vector3d::Zero();
  }
}

double PrimitiveArea(int type, const double* size) {
  switch (type) {
    case mjGEOM_SPHERE:
      return 4 * M_PI * size[0] * size[0];
    case mjGEOM_BOX:
      return 8 * (size[0] * size[1] + size[1] * size[2] + size[0] * size[2]);
    case mjGEOM_CYLINDER:
      return 4 * M_PI * size[0] * size[1] + 2 * M_PI * size[0] * size[0];
    case mjGEOM_CAPSULE:
      return 4 * M_PI * size[0] * size[1] + 4 * M_PI * size[0] * size[0];
    default:
      return 0;
  }
}

}  // namespace

Camera MakeCamera(const CameraSpec& spec) {
  Camera camera;
  auto& k = camera.intrinsics;
  k.width = spec.width;
  k.height = spec.height;
  k.fy = 0.5 * spec.height / std::tan(0.5 * spec.fovy_deg * M_PI / 180.0);
  k.fx = k.fy;
  k.cx = 0.5 * (spec.width - 1);
  k.cy = 0.5 * (spec.height - 1);
  const Eigen::Vector3d position(spec.position.data()), target(spec.look_at.data());
  const Eigen::Vector3d forward = (target - position).normalized();
  Eigen::Vector3d right = forward.cross(Eigen::Vector3d::UnitZ());
  if (right.norm() < 1e-6) right = Eigen::Vector3d::UnitY();  // looking straight down
  right.normalize();
  const Eigen::Vector3d down = forward.cross(right);
  Eigen::Matrix3d r;
  r << right, down, forward;
  camera.pose.rotation = core::Quat(r).normalized();
  camera.pose.translation = position;
  camera.pose = camera.pose * CorrectionPose(spec.correction);
  return camera;
}

core::Pose CorrectionPose(const std::array<double, 6>& c) {
  return {Eigen::Vector3d(c[3], c[4], c[5]), core::ExpMap(Eigen::Vector3d(c[0], c[1], c[2]))};
}

std::array<double, 6> CorrectionArray(const core::Pose& correction) {
  const Eigen::Vector3d r = core::LogMap(correction.rotation);
  const Eigen::Vector3d& t = correction.translation;
  return {r.x(), r.y(), r.z(), t.x(), t.y(), t.z()};
}

Workspace MakeWorkspace(const WorkspaceSpec& spec) {
  Workspace w;
  for (int i = 0; i < 3; ++i) {
    w.min[i] = static_cast<float>(spec.min[i]);
    w.max[i] = static_cast<float>(spec.max[i]);
  }
  return w;
}

RayCaster::RayCaster(const Camera& camera, const mjModel* m) : camera_(camera), scene_(m) {
  const auto& k = camera.intrinsics;
  directions_.resize(3 * k.width * k.height);
  z_scale_.resize(k.width * k.height);
  for (int v = 0; v < k.height; ++v)
    for (int u = 0; u < k.width; ++u) {
      const Eigen::Vector3d ray =
          Eigen::Vector3d((u - k.cx) / k.fx, (v - k.cy) / k.fy, 1.0).normalized();
      const int i = v * k.width + u;
      std::copy(ray.data(), ray.data() + 3, directions_.data() + 3 * i);
      z_scale_[i] = ray.z();
    }
}

void RayCaster::Render(const mjModel* m, const mjData* d, const core::Pose& base, float* depth,
                       uint8_t* rgb, bool include_robot, int* geom) {
  const auto& k = camera_.intrinsics;
  const core::Pose world_from_camera = base * camera_.pose;
  const RowMat3 rotation = world_from_camera.rotation.toRotationMatrix();
  const Eigen::Vector3f origin = world_from_camera.translation.cast<float>();
  scene_.Update(m, d, include_robot ? 0u : 1u << kRobotGeomGroup);
  const int n = k.width * k.height;
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3f dir =
        (rotation * Eigen::Map<const Eigen::Vector3d>(&directions_[3 * i])).cast<float>();
    const GeomScene::Hit hit = scene_.Cast(origin.data(), dir.data());
    depth[i] = hit.geom >= 0 ? static_cast<float>(hit.distance * z_scale_[i]) : 0.0f;
    if (geom) geom[i] = hit.geom;
    if (!rgb) continue;
    if (hit.geom < 0) {
      rgb[3 * i] = rgb[3 * i + 1] = rgb[3 * i + 2] = 0;
      continue;
    }
    const float* color = GeomRgba(m, hit.geom);
    // Surfaces darkened with distance from the camera.
    const double shade = std::clamp(1.0 - 0.25 * (hit.distance - 0.5), 0.55, 1.0);
    for (int c = 0; c < 3; ++c)
      rgb[3 * i + c] = static_cast<uint8_t>(std::clamp(color[c] * shade, 0.0, 1.0) * 255.0 + 0.5);
  }
}

std::vector<uint8_t> DepthEdges(const float* depth, int width, int height, double jump) {
  std::vector<uint8_t> edge(static_cast<size_t>(width) * height, 0);
  auto differs = [&](int i, int j) {
    return depth[j] <= 0 || std::abs(depth[j] - depth[i]) > jump;
  };
  for (int v = 0; v < height; ++v)
    for (int u = 0; u < width; ++u) {
      const int i = v * width + u;
      if (depth[i] <= 0) continue;
      edge[i] = (u > 0 && differs(i, i - 1)) || (u + 1 < width && differs(i, i + 1)) ||
                (v > 0 && differs(i, i - width)) || (v + 1 < height && differs(i, i + width));
    }
  return edge;
}

void AddDepthNoise(float* depth, int width, int height, const DepthNoise& noise, core::Rng& rng,
                   const int* geom, const std::vector<double>& surface_dropout) {
  if (noise.off()) return;
  const int count = width * height;
  const std::vector<uint8_t> edge = noise.edge_dropout > 0
                                        ? DepthEdges(depth, width, height, noise.edge_jump)
                                        : std::vector<uint8_t>(count, 0);
  for (int i = 0; i < count; ++i) {
    if (depth[i] <= 0) continue;
    const double lose = edge[i] ? noise.edge_dropout : noise.dropout;
    if (lose > 0 && rng.Uniform() < lose) {
      depth[i] = 0;
      continue;
    }
    const double surface =
        geom && geom[i] >= 0 && geom[i] < static_cast<int>(surface_dropout.size())
            ? surface_dropout[geom[i]]
            : 0.0;
    if (surface > 0 && rng.Uniform() < surface) {
      depth[i] = 0;
      continue;
    }
    double z = depth[i];
    z += rng.Normal() * (noise.sigma0 + noise.sigma_z2 * z * z);
    if (noise.quantization > 0) z = noise.quantization * std::round(z / noise.quantization);
    depth[i] = static_cast<float>(std::max(0.0, z));
  }
}

std::vector<double> SurfaceDropoutByGeom(const mjModel* m, const DepthNoise& noise) {
  if (noise.surfaces.empty()) return {};
  std::vector<double> out(m->ngeom, 0.0);
  for (size_t i = 0; i < noise.surfaces.size(); ++i) {
    const SurfaceDropout& s = noise.surfaces[i];
    const int g = mj_name2id(m, mjOBJ_GEOM, s.geom.c_str());
    if (g < 0)
      throw core::ConfigError("camera.noise.surfaces[" + std::to_string(i) + "]", "geom",
                              "a geom of the scene ('" + s.geom + "' is not one)");
    out[g] = s.dropout;
  }
  return out;
}

int DepthToPoints(const Camera& camera, const float* depth, const Workspace& workspace,
                  float* xyz) {
  const auto& k = camera.intrinsics;
  const Eigen::Matrix3f r = camera.pose.rotation.toRotationMatrix().cast<float>();
  const Eigen::Vector3f t = camera.pose.translation.cast<float>();
  int count = 0;
  for (int v = 0; v < k.height; ++v)
    for (int u = 0; u < k.width; ++u) {
      const float z = depth[v * k.width + u];
      if (z <= 0) continue;
      const Eigen::Vector3f local(static_cast<float>((u - k.cx) / k.fx) * z,
                                  static_cast<float>((v - k.cy) / k.fy) * z, z);
      const Eigen::Vector3f p = r * local + t;
      if (!workspace.Contains(p.data())) continue;
      std::copy(p.data(), p.data() + 3, xyz + 3 * count);
      ++count;
    }
  return count;
}

SurfaceSampler::SurfaceSampler(const mjModel* m, unsigned groups, double density, int min_per_geom,
                               int max_per_geom, const std::function<bool(int)>& keep) {
  core::Rng rng(0x5a3);
  for (int g = 0; g < m->ngeom; ++g) {
    if (!(groups & (1u << m->geom_group[g])) || (keep && !keep(g))) continue;
    const int type = m->geom_type[g];
    const double* size = m->geom_size + 3 * g;
    if (type == mjGEOM_MESH) {
      const int mesh = m->geom_dataid[g];
      const int vert0 = m->mesh_vertadr[mesh], face0 = m->mesh_faceadr[mesh];
      const int faces = m->mesh_facenum[mesh];
      std::vector<double> cumulative(faces);
      double total = 0;
      auto vertex = [&](int f, int c) {
        const int idx = vert0 + m->mesh_face[3 * (face0 + f) + c];
        return Eigen::Vector3d(m->mesh_vert[3 * idx], m->mesh_vert[3 * idx + 1],
                               m->mesh_vert[3 * idx + 2]);
      };
      for (int f = 0; f < faces; ++f) {
        total += 0.5 * (vertex(f, 1) - vertex(f, 0)).cross(vertex(f, 2) - vertex(f, 0)).norm();
        cumulative[f] = total;
      }
      const int count = std::clamp(static_cast<int>(total * density), min_per_geom, max_per_geom);
      for (int s = 0; s < count && total > 0; ++s) {
        const int f = static_cast<int>(
            std::lower_bound(cumulative.begin(), cumulative.end(), rng.Uniform(0, total)) -
            cumulative.begin());
        double a = rng.Uniform(), b = rng.Uniform();
        if (a + b > 1) a = 1 - a, b = 1 - b;
        const Eigen::Vector3d p =
            vertex(f, 0) + a * (vertex(f, 1) - vertex(f, 0)) + b * (vertex(f, 2) - vertex(f, 0));
        geom_.push_back(g);
        for (int c = 0; c < 3; ++c) local_.push_back(static_cast<float>(p[c]));
        scaled_.push_back(0);
      }
      continue;
    }
    const double area = PrimitiveArea(type, size);
    if (area <= 0) continue;  // planes, heightfields: not sampled
    const int count = std::clamp(static_cast<int>(area * density), min_per_geom, max_per_geom);
    for (int s = 0; s < count; ++s) {
      const Eigen::Vector3d p = SamplePrimitive(type, size, rng);
      geom_.push_back(g);
      for (int c = 0; c < 3; ++c) local_.push_back(static_cast<float>(p[c]));
      scaled_.push_back(1);
    }
  }
}

int SurfaceSampler::Transform(const mjModel* m, const mjData* d, const core::Pose& base,
                              const Workspace& workspace, float* xyz) const {
  const core::Pose to_base = base.Inverse();
  const RowMat3 base_rotation = to_base.rotation.toRotationMatrix();
  int count = 0;
  for (std::size_t s = 0; s < geom_.size(); ++s) {
    const int g = geom_[s];
    const float* l = &local_[3 * s];
    Eigen::Vector3d p(l[0], l[1], l[2]);
    if (scaled_[s]) {
      const double* size = m->geom_size + 3 * g;
      switch (m->geom_type[g]) {
        case mjGEOM_SPHERE:
          p *= size[0];
          break;
        case mjGEOM_BOX:
          p = p.cwiseProduct(Eigen::Vector3d(size[0], size[1], size[2]));
          break;
        case mjGEOM_CYLINDER:
          p = Eigen::Vector3d(p.x() * size[0], p.y() * size[0], p.z() * size[1]);
          break;
        case mjGEOM_CAPSULE:
          p = Eigen::Vector3d(p.x() * size[0], p.y() * size[0], p.z() * size[1]);
          break;
      }
    }
    const Eigen::Map<const RowMat3> rotation(d->geom_xmat + 9 * g);
    const Eigen::Vector3d world = rotation * p + Eigen::Vector3d(d->geom_xpos + 3 * g);
    const Eigen::Vector3f local = (base_rotation * world + to_base.translation).cast<float>();
    if (!workspace.Contains(local.data())) continue;
    std::copy(local.data(), local.data() + 3, xyz + 3 * count);
    ++count;
  }
  return count;
}

void ResamplePoints(const float* points, int n, int count, core::Rng& rng, float* out, int stride) {
  if (n <= 0) {
    std::fill(out, out + stride * count, 0.0f);
    return;
  }
  if (n >= count) {
    // Partial Fisher-Yates over indices, without allocating: pick `count` distinct indices by
    // selection sampling (Knuth's algorithm S), which keeps the points' order.
    int chosen = 0;
    for (int i = 0; i < n && chosen < count; ++i) {
      if (rng.Uniform() * (n - i) < count - chosen) {
        std::copy(points + stride * i, points + stride * (i + 1), out + stride * chosen);
        ++chosen;
      }
    }
    return;
  }
  std::copy(points, points + stride * n, out);
  for (int i = n; i < count; ++i) {
    const int j = static_cast<int>(rng.Index(n));
    std::copy(points + stride * j, points + stride * (j + 1), out + stride * i);
  }
}

CloudMaker::CloudMaker(const Task& task, const mjModel* m, const Options& options)
    : options_(options),
      workspace_(MakeWorkspace(task.spec().workspace)),
      caster_(MakeCamera(task.spec().camera), m),
      scene_sampler_(m, ~(1u << kRobotGeomGroup)),
      arm_sampler_(m, 1u << kRobotGeomGroup),
      robot_(task.index().robot),
      mask_(options.rendered ? std::make_unique<RobotMask>(task.robot()) : nullptr),
      surface_dropout_(options.rendered ? SurfaceDropoutByGeom(m, options.noise)
                                        : std::vector<double>{}) {
  const auto& k = caster_.camera().intrinsics;
  depth_.resize(k.width * k.height);
  if (!surface_dropout_.empty()) geom_.resize(k.width * k.height);
  scratch_.resize(
      3 * std::max({k.width * k.height, scene_sampler_.capacity(), arm_sampler_.capacity()}));
}

CloudMaker::~CloudMaker() = default;

void CloudMaker::Make(const mjModel* m, const mjData* d, const core::Pose& base, core::Rng& rng,
                      float* scene, float* arm) {
  int n = 0;
  if (options_.rendered) {
    int* geom = geom_.empty() ? nullptr : geom_.data();
    caster_.Render(m, d, base, depth_.data(), nullptr, false, geom);
    const auto& k = caster_.camera().intrinsics;
    AddDepthNoise(depth_.data(), k.width, k.height, options_.noise, rng, geom, surface_dropout_);
    ArmVector q;
    for (int j = 0; j < kArmDof; ++j) q[j] = d->qpos[robot_.arm_qpos[j]];
    mask_->Pose(q, d->qpos[robot_.finger_qpos[0]] + d->qpos[robot_.finger_qpos[1]]);
    mask_->Remove(caster_.camera(), depth_, kArmDepthMargin, kArmGrowPixels);
    n = DepthToPoints(caster_.camera(), depth_.data(), workspace_, scratch_.data());
  } else {
    n = scene_sampler_.Transform(m, d, base, workspace_, scratch_.data());
  }
  ResamplePoints(scratch_.data(), n, options_.scene_points, rng, scene);
  const int arm_n = arm_sampler_.Transform(m, d, base, workspace_, scratch_.data());
  ResamplePoints(scratch_.data(), arm_n, options_.arm_points, rng, arm);
}

}  // namespace twinforge::sim
