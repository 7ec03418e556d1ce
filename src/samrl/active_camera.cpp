#include "samrl/active_camera.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>

#include "core/error.h"
#include "sim/model.h"

namespace twinforge::samrl {

namespace {

const auto kDouble = torch::TensorOptions().dtype(torch::kFloat64);

// TargetVisibility's colours: its score counts the red, so anything else drawn into its views
// (the occluders a look is told of) is drawn in the colour of the rest.
const Eigen::Vector3d kTargetColor(1, 0, 0), kRestColor(0, 0, 1);

double Score(const real2sim::RasterMesh& scene, const core::PinholeIntrinsics& intrinsics,
             const OrbitMount& mount, const ViewScore& score, double azimuth, double elevation,
             const real2sim::SoftRasterOptions& raster) {
  torch::NoGradGuard no_grad;
  const auto angles = torch::tensor({azimuth, elevation}, kDouble);
  return score(real2sim::SoftRasterize(scene, intrinsics, OrbitPose(mount, angles), raster))
      .item<double>();
}

void CheckMount(const OrbitMount& mount) {
  if (!(mount.radius > 0) || !(mount.min_azimuth <= mount.max_azimuth) ||
      !(mount.min_elevation <= mount.max_elevation) || mount.min_elevation <= -M_PI / 2 ||
      mount.max_elevation >= M_PI / 2)
    throw core::Error(
        "orbit mount: needs a positive radius, ordered limits and elevations strictly between "
        "-90 and 90 degrees");
}

}  // namespace

TargetView TargetVisibility(real2sim::TwinGeometry& twin, const std::array<double, 7>& q,
                            double gripper_width, const std::vector<std::string>& target_bodies) {
  const mjModel* m = twin.model();
  std::vector<int> bodies;
  for (const std::string& name : target_bodies) {
    const int b = mj_name2id(m, mjOBJ_BODY, name.c_str());
    if (b < 0) throw core::Error("active camera: the twin has no body named '" + name + "'");
    bodies.push_back(b);
  }
  const auto color = [&](int geom) {
    const bool target =
        std::find(bodies.begin(), bodies.end(), m->geom_bodyid[geom]) != bodies.end();
    return target ? kTargetColor : kRestColor;
  };
  return {twin.Posed(q, gripper_width, color),
          [](const real2sim::SoftImage& image) { return image.rgb.select(2, 0).mean() * 100.0; }};
}

real2sim::CameraTensor OrbitPose(const OrbitMount& mount, const torch::Tensor& angles) {
  const torch::Tensor az = angles[0], el = angles[1];
  const torch::Tensor center =
      torch::tensor({mount.center.x(), mount.center.y(), mount.center.z()}, kDouble);
  const torch::Tensor eye =
      center + mount.radius * torch::stack({torch::cos(el) * torch::cos(az),
                                            torch::cos(el) * torch::sin(az), torch::sin(el)});
  // Forward toward the centre; right = forward x up; down = forward x right (OpenCV axes).
  const torch::Tensor forward = (center - eye) / mount.radius;
  const torch::Tensor up = torch::tensor({0.0, 0.0, 1.0}, kDouble);
  torch::Tensor right = torch::cross(forward, up, 0);
  right = right / right.norm();
  const torch::Tensor down = torch::cross(forward, right, 0);
  return {torch::stack({right, down, forward}, 1), eye};
}

core::Pose OrbitPose(const OrbitMount& mount, double azimuth, double elevation) {
  return real2sim::ToPose(OrbitPose(mount, torch::tensor({azimuth, elevation}, kDouble)));
}

ViewChoice AscendView(const real2sim::RasterMesh& scene, const core::PinholeIntrinsics& intrinsics,
                      const OrbitMount& mount, const ViewScore& score, double azimuth,
                      double elevation, const ViewSearchOptions& options) {
  CheckMount(mount);
  torch::Tensor angles =
      torch::tensor({std::clamp(azimuth, mount.min_azimuth, mount.max_azimuth),
                     std::clamp(elevation, mount.min_elevation, mount.max_elevation)},
                    kDouble.requires_grad(true));
  torch::optim::Adam adam({angles}, torch::optim::AdamOptions(options.learning_rate));
  ViewChoice best;
  best.score = -INFINITY;
  for (int step = 0; step <= options.steps; ++step) {
    const torch::Tensor s =
        score(real2sim::SoftRasterize(scene, intrinsics, OrbitPose(mount, angles), options.raster));
    const double value = s.item<double>();
    if (!std::isfinite(value))
      throw core::NumericError("active camera: the view score is " + std::to_string(value) +
                               " at azimuth " + std::to_string(angles[0].item<double>()) +
                               ", elevation " + std::to_string(angles[1].item<double>()));
    best.scores.push_back(value);
    if (value > best.score) {
      best.score = value;
      best.azimuth = angles[0].item<double>();
      best.elevation = angles[1].item<double>();
    }
    if (step == options.steps) break;
    adam.zero_grad();
    (-s).backward();
    adam.step();
    torch::NoGradGuard no_grad;
    angles[0].clamp_(mount.min_azimuth, mount.max_azimuth);
    angles[1].clamp_(mount.min_elevation, mount.max_elevation);
  }
  return best;
}

ViewChoice SampleView(const real2sim::RasterMesh& scene, const core::PinholeIntrinsics& intrinsics,
                      const OrbitMount& mount, const ViewScore& score, core::Rng& rng,
                      const ViewSearchOptions& options) {
  CheckMount(mount);
  ViewChoice best;
  best.score = -INFINITY;
  for (int i = 0; i < options.samples; ++i) {
    const double az = rng.Uniform(mount.min_azimuth, mount.max_azimuth);
    const double el = rng.Uniform(mount.min_elevation, mount.max_elevation);
    const double value = Score(scene, intrinsics, mount, score, az, el, options.raster);
    best.scores.push_back(value);
    if (value > best.score) {
      best.score = value;
      best.azimuth = az;
      best.elevation = el;
    }
  }
  return best;
}

ViewChoice ChooseView(const real2sim::RasterMesh& scene, const core::PinholeIntrinsics& intrinsics,
                      const OrbitMount& mount, const ViewScore& score, core::Rng& rng,
                      const ViewSearchOptions& options) {
  const ViewChoice sampled = SampleView(scene, intrinsics, mount, score, rng, options);
  ViewChoice refined =
      AscendView(scene, intrinsics, mount, score, sampled.azimuth, sampled.elevation, options);
  refined.scores.insert(refined.scores.begin(), sampled.scores.begin(), sampled.scores.end());
  return refined;
}

OrbitMount ObjectsMount(const sim::Task& twin) {
  sim::Env env(std::make_shared<const sim::Task>(twin.spec()));
  env.Reset(0, 0);
  OrbitMount mount;
  mount.center.setZero();
  for (int body : twin.index().object_bodies) mount.center += env.BodyPose(body).translation;
  if (!twin.index().object_bodies.empty())
    mount.center /= double(twin.index().object_bodies.size());
  const sim::CameraSpec& camera = twin.spec().camera;
  const std::array<double, 2> azimuth = camera.mount_azimuth.value_or(std::array{-2.5, 2.5});
  const std::array<double, 2> elevation = camera.mount_elevation.value_or(std::array{0.8, 1.3});
  mount.radius = 0.6;
  mount.min_azimuth = azimuth[0];
  mount.max_azimuth = azimuth[1];
  mount.min_elevation = elevation[0];
  mount.max_elevation = elevation[1];
  return mount;
}

TargetView TargetVisibilityAtRest(real2sim::TwinGeometry& twin, const sim::Task& task,
                                  const std::vector<std::string>& targets) {
  sim::Env env(std::make_shared<const sim::Task>(task.spec()));
  env.Reset(0, 0);
  const sim::ArmVector arm = env.ArmPositions();
  std::array<double, 7> q;
  for (int i = 0; i < 7; ++i) q[i] = arm[i];
  return TargetVisibility(twin, q, 2 * env.FingerOpening(), targets);
}

core::PinholeIntrinsics LookSearchCamera() { return {40, 30, 36, 36, 19.5, 14.5}; }

ViewSearchOptions LookSearch() {
  ViewSearchOptions o;
  o.samples = 24;
  o.steps = 30;
  return o;
}

core::Pose BestFixedView(real2sim::TwinGeometry& twin, const sim::Task& task,
                         const std::vector<std::string>& targets, const OrbitMount& mount,
                         const core::PinholeIntrinsics& search, const ViewSearchOptions& options,
                         uint64_t seed) {
  const TargetView view = TargetVisibilityAtRest(twin, task, targets);
  core::Rng rng(seed);
  const ViewChoice choice = ChooseView(view.mesh, search, mount, view.score, rng, options);
  spdlog::info("best fixed view: azimuth {:.2f}, elevation {:.2f}, targets fill {:.1f}%",
               choice.azimuth, choice.elevation, choice.score);
  return OrbitPose(mount, choice.azimuth, choice.elevation);
}

TargetView BelievedView(real2sim::TwinGeometry& twin, const std::array<double, 7>& q,
                        double gripper_width,
                        const std::vector<std::pair<std::string, core::Pose>>& objects,
                        const std::string& held, const std::vector<std::string>& targets,
                        const std::vector<Occluder>& occluders) {
  const mjModel* m = twin.model();
  for (const auto& [name, pose] : objects) {
    const int b = mj_name2id(m, mjOBJ_BODY, name.c_str());
    if (b >= 0 && sim::FreeJointOf(m, b) >= 0) twin.PlaceBody(b, pose);
  }
  std::vector<std::string> wanted;
  for (const auto& t : targets)
    if (t != held) wanted.push_back(t);
  TargetView view = TargetVisibility(twin, q, gripper_width, wanted);
  if (!occluders.empty()) {
    std::vector<real2sim::RasterMesh> parts{view.mesh};
    for (const Occluder& o : occluders)
      parts.push_back(real2sim::BoxMesh(o.center, o.size, kRestColor));
    view.mesh = real2sim::JoinMeshes(parts);
  }
  return view;
}

Look ActiveLook(reality::Robot& robot, real2sim::TwinGeometry& twin,
                const std::vector<std::string>& targets, const OrbitMount& mount,
                const core::PinholeIntrinsics& search, const core::PinholeIntrinsics& capture,
                const ViewSearchOptions& options, uint64_t seed, LookScore score) {
  return [&robot, &twin, targets, mount, search, capture, options, seed,
          score](const LookContext& context) {
    const reality::Observation& o = context.observation;
    std::array<double, 7> q;
    for (int i = 0; i < 7; ++i) q[i] = o.q[i];
    const TargetView view = BelievedView(twin, q, o.gripper_width, context.objects, context.held,
                                         targets, context.occluders);
    core::Rng rng(seed);
    const ViewChoice choice =
        ChooseView(view.mesh, search, mount, score ? score(context) : view.score, rng, options);
    spdlog::debug("active look: azimuth {:.2f}, elevation {:.2f}, {} {:.2f}; {} occluders",
                  choice.azimuth, choice.elevation, score ? "Q" : "targets fill (%)", choice.score,
                  context.occluders.size());
    return std::vector<reality::RgbdFrame>{
        robot.Capture({OrbitPose(mount, choice.azimuth, choice.elevation), capture})};
  };
}

}  // namespace twinforge::samrl
