// Grader for `twinforge calibrate` on a proxy world (reads the hidden world: never part of the
// pipeline). Calibrates the camera from the given frames, optionally starting from a pose made
// worse by a known offset, and prints the error of our correction and of Open3D's ICP against
// the world's true camera mount, with the depth fit at the truth for reference.
//
//   calibrate_bench --twin DIR --frames DIR --world open_drawer [--start-mm 0 --start-deg 0]
#include <CLI/CLI.hpp>
#include <iostream>

#include "core/config.h"
#include "core/scan.h"
#include "learn/torch_runtime.h"
#include "real2sim/calibrate/calibrate.h"
#include "reality/proxy_reality.h"
#include "sim/camera.h"

using namespace twinforge;

int main(int argc, char** argv) {
  learn::PinMathThreads(1);
  learn::KeepLargeBuffers();
  CLI::App app("calibrate_bench");
  std::string twin, frames_dir, world;
  double start_mm = 0, start_deg = 0;
  real2sim::CalibrateOptions options;
  app.add_option("--twin", twin)->required();
  app.add_option("--frames", frames_dir)->required();
  app.add_option("--world", world)->required();
  app.add_option("--start-mm", start_mm, "extra start error (mm), on top of the mount's");
  app.add_option("--start-deg", start_deg, "extra start error (deg)");
  std::string config;
  app.add_option("--config", config, "calibration options (JSON/YAML)");
  CLI11_PARSE(app, argc, argv);
  if (!config.empty()) options = core::LoadConfig<real2sim::CalibrateOptions>(config);

  const reality::WorldSpec spec = reality::LoadWorldSpec(reality::ResolveWorldDir(world));
  // The frames report the camera where its calibration says; it is really at reported * truth.
  const core::Pose truth{Eigen::Vector3d(spec.camera_offset.data()),
                         core::FromRollPitchYaw(spec.camera_rotation[0], spec.camera_rotation[1],
                                                spec.camera_rotation[2])};
  core::Scan frames = core::ReadScan(frames_dir);
  // A worse start: every reported pose moved by `extra`; the truth relative to it follows.
  const core::Pose extra{
      Eigen::Vector3d(1, -1, 1).normalized() * start_mm * 1e-3,
      core::ExpMap(Eigen::Vector3d(1, 1, -1).normalized() * start_deg * M_PI / 180)};
  for (auto& f : frames.frames) f.camera_to_base = f.camera_to_base * extra;
  const core::Pose target = extra.Inverse() * truth;
  const sim::TaskSpec task =
      sim::LoadTaskSpec((std::filesystem::path(twin) / "task.yaml").string());
  const auto result = real2sim::CalibrateCamera(task, frames, options);
  auto error = [&](const core::Pose& c) {
    const core::Pose e = c.Inverse() * target;
    return nlohmann::json{
        {"mm", e.translation.norm() * 1e3},
        {"deg", core::AngleBetween(e.rotation, core::Quat::Identity()) * 180 / M_PI}};
  };
  const auto fit_truth = real2sim::FitFrames(task, frames, target, options);
  double truth_median = 0;
  for (const auto& f : fit_truth) truth_median += f.median_depth_error / fit_truth.size();
  nlohmann::json out = {{"start", error(core::Pose::Identity())},
                        {"ours", error(result.correction)},
                        {"icp", error(result.icp_correction)},
                        {"median_depth_error_at_truth_mm", truth_median * 1e3},
                        {"calibration", real2sim::ToJson(result)}};
  std::cout << out.dump(2) << "\n";
  return 0;
}
