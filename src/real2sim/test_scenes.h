// Synthetic scans for real2sim tests: a MuJoCo scene seen from two rings of cameras with a
// little depth noise, written the way `scan capture` writes a scan.
#pragma once

#include <array>
#include <cmath>
#include <filesystem>
#include <string>

#include "core/rng.h"
#include "core/scan.h"
#include "sim/camera.h"
#include "sim/model.h"
#include "sim/robot.h"

namespace twinforge::real2sim::testing {

inline core::Scan SyntheticScan(const std::filesystem::path& dir, const std::string& xml,
                                const std::array<double, 3>& look_at, double radius = 0.8) {
  const sim::ModelPtr m = sim::LoadModelFromText(xml);
  const sim::DataPtr d = sim::MakeData(m.get());
  mj_forward(m.get(), d.get());
  const sim::RobotSpec robot = sim::LoadRobotSpec(sim::DefaultRobotPath());
  std::filesystem::remove_all(dir);
  core::ScanWriter writer(dir, "synthetic", "panda");
  core::Rng rng(3);
  for (int i = 0; i < 16; ++i) {
    const double azimuth = -1.6 + 3.2 * (i % 8) / 7.0, elevation = i < 8 ? 0.5 : 0.9;
    sim::CameraSpec spec;
    spec.width = 320;
    spec.height = 240;
    spec.look_at = look_at;
    spec.position = {look_at[0] + radius * std::cos(elevation) * std::cos(azimuth),
                     look_at[1] + radius * std::cos(elevation) * std::sin(azimuth),
                     look_at[2] + radius * std::sin(elevation)};
    const sim::Camera camera = sim::MakeCamera(spec);
    sim::RayCaster caster(camera, m.get());
    const std::size_t n = 320 * 240;
    std::vector<float> depth(n);
    std::vector<uint8_t> rgb(3 * n);
    caster.Render(m.get(), d.get(), core::Pose{}, depth.data(), rgb.data());
    std::vector<uint16_t> mm(n);
    for (std::size_t p = 0; p < n; ++p)
      mm[p] = depth[p] > 0 ? uint16_t(std::lround(1000 * (depth[p] + 0.001 * rng.Normal()))) : 0;
    core::ScanFrameInfo info;
    info.intrinsics = camera.intrinsics;
    info.camera_to_base = camera.pose;
    std::copy(robot.home.begin(), robot.home.end(), info.joint_positions.begin());
    info.gripper_width = 0.08;
    writer.Add(info, rgb, mm);
  }
  return writer.scan();
}

}  // namespace twinforge::real2sim::testing
