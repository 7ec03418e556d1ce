#include "samrl/pose_bench.h"

#include <cmath>
#include <string>
#include <vector>

#include "core/error.h"
#include "core/measure.h"
#include "core/thread_pool.h"
#include "real2sim/mesh.h"
#include "reality/proxy_reality.h"
#include "samrl/active_camera.h"
#include "samrl/pose_estimate.h"
#include "samrl/twin_actor.h"
#include "sim/camera.h"
#include "sim/geom_scene.h"
#include "sim/model.h"

namespace twinforge::samrl {

nlohmann::json RunPoseBench(std::shared_ptr<const sim::Task> twin,
                            const PoseBenchOptions& options) {
  const sim::TaskSpec& spec = twin->spec();
  if (spec.objects.empty()) throw core::Error("pose bench: task " + spec.name + " has no objects");
  // The twin run as a robot with an ideal depth sensor (ProxyReality::SimulatedTwin): its frame
  // as a robot would send it, the arm in view.
  const auto robot =
      reality::ProxyReality::SimulatedTwin(spec, reality::ProxyReality::Sensor::kIdeal);
  const reality::Observation o = robot->Reset({options.seed, options.level});
  const sim::Env& env = robot->hidden_env();
  const mjModel* m = env.model();
  sim::Camera camera = sim::MakeCamera(spec.camera);
  if (options.from_mount) {
    const OrbitMount mount = ObjectsMount(*twin);
    camera.pose = OrbitPose(mount, 0.5 * (mount.min_azimuth + mount.max_azimuth),
                            0.5 * (mount.min_elevation + mount.max_elevation));
  }
  const reality::RgbdFrame frame =
      robot->Capture({camera.pose, ScaleIntrinsics(camera.intrinsics, options.capture_scale)});

  PoseEstimateOptions every_point;
  every_point.start_points = 0;
  ObjectPoseEstimator estimator(twin, spec.objects);
  const ObjectPoseEstimator exhaustive(twin, spec.objects, every_point);
  const std::vector<Eigen::Vector3d> foreground =
      estimator.Foreground(FramePoints(frame), o.q, o.gripper_width);
  if (foreground.empty())
    throw core::Error("pose bench: task " + spec.name +
                      ": the frame shows nothing the twin's fixed geometry and arm do not explain");

  // The baseline: the foreground's closest points on the objects' surfaces, in one query.
  std::vector<int> ids;
  for (const auto& body : spec.objects) ids.push_back(mj_name2id(m, mjOBJ_BODY, body.c_str()));
  const real2sim::SurfaceQuery objects(real2sim::PosedGeoms(m, env.data(), env.base(), [&](int g) {
    for (const int id : ids)
      if (sim::InSubtree(m, m->geom_bodyid[g], id) && sim::GeomShown(m, g)) return true;
    return false;
  }));

  std::vector<ObjectPose> fit, fit_every;
  std::vector<double> raw_rate, seconds, seconds_every, passes, passes_every, speedup;
  for (int r = 0; r < options.repeats; ++r) {
    // Raw passes for at least half a second, then both estimates, back to back.
    int n = 0;
    const auto t0 = core::Clock::now();
    do {
      objects.Closest(foreground, 1);
      ++n;
    } while (core::SecondsSince(t0) < 0.5);
    const double pass = core::SecondsSince(t0) / n;
    raw_rate.push_back(double(foreground.size()) / pass);
    seconds.push_back(core::Seconds([&] { fit = estimator.Estimate(foreground); }));
    seconds_every.push_back(core::Seconds([&] { fit_every = exhaustive.Estimate(foreground); }));
    passes.push_back(seconds.back() / pass);
    passes_every.push_back(seconds_every.back() / pass);
    speedup.push_back(seconds_every.back() / seconds.back());
  }

  // Each fit's error against the reset's pose: the look-alike turn nearest it.
  const auto errors = [&](const std::vector<ObjectPose>& poses) {
    nlohmann::json out = nlohmann::json::object();
    for (std::size_t i = 0; i < poses.size(); ++i) {
      const core::Pose truth = env.BodyPose(ids[i]);
      const core::Pose pose = estimator.NearestLookAlike(int(i), poses[i].pose, truth);
      out[poses[i].body] = {
          {"seen", poses[i].seen},
          {"starts", poses[i].starts},
          {"mm", (pose.translation - truth.translation).norm() * 1e3},
          {"deg", core::AngleBetween(pose.rotation, truth.rotation) * 180 / M_PI}};
    }
    return out;
  };
  return {{"task", spec.name},
          {"from_mount", options.from_mount},
          {"seed", options.seed},
          {"level", options.level},
          {"repeats", options.repeats},
          {"threads", core::DefaultThreadCount()},
          {"foreground_points", foreground.size()},
          {"raw_closest_points_per_s", core::Median(raw_rate)},
          {"estimate_seconds", core::Median(seconds)},
          {"estimate_in_raw_passes", core::Median(passes)},
          {"estimate_seconds_every_point", core::Median(seconds_every)},
          {"estimate_in_raw_passes_every_point", core::Median(passes_every)},
          {"speedup_of_start_points", core::Median(speedup)},
          {"errors", errors(fit)},
          {"errors_every_point", errors(fit_every)}};
}

}  // namespace twinforge::samrl
