// The proxy reality: a hidden world that stands in for a real robot and scene.
//
// A world is a directory (docs/reality-world.md): `world.yaml` with the hidden settings below,
// and a task file with its own detailed scene (meshes, its own masses, frictions and damping),
// success predicates (the oracle) and randomization levels. Only `twinforge reality serve` and
// graders open it; pipeline stages reach it through reality::Robot, over the bridge.
//
// What differs from a twin, on purpose: the scene's geometry and physical parameters (in the
// world's MJCF), the arm's low-level controller (gains, a target interpolator, latency), the
// camera's true mount (off its reported extrinsics) and a depth sensor with structured-light
// noise, quantization, missing pixels at depth edges and holes on dark or shiny surfaces.
#pragma once

#include <array>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "reality/robot.h"
#include "reality/teleop.h"
#include "sim/env.h"
#include "sim/servo_lag.h"

namespace twinforge::reality {

struct DepthSensorSpec {
  double sigma0 = 0.001;         // m, noise at zero range
  double sigma_z2 = 0.002;       // 1/m: noise grows with z^2
  double quantization = 0.001;   // m, depth reported in steps of this
  double edge_jump = 0.02;       // m, a neighbour this much farther or nearer marks an edge
  double edge_dropout = 0.5;     // probability that an edge pixel returns nothing
  double dark_luminance = 0.12;  // surfaces darker than this (0..1) may return nothing
  double dark_dropout = 0.6;
  double shiny_specular = 0.7;  // materials at least this specular may return nothing
  double shiny_dropout = 0.5;
  double max_range = 2.5;  // m
  template <class A>
  void Serialize(A& a) {
    a("sigma0", sigma0);
    a("sigma_z2", sigma_z2);
    a("quantization", quantization);
    a("edge_jump", edge_jump);
    a("edge_dropout", edge_dropout);
    a("dark_luminance", dark_luminance);
    a("dark_dropout", dark_dropout);
    a("shiny_specular", shiny_specular);
    a("shiny_dropout", shiny_dropout);
    a("max_range", max_range);
    a.Require(sigma0 >= 0 && sigma_z2 >= 0, "sigma0", "non-negative noise");
    a.Require(quantization >= 0, "quantization", "a non-negative step in m");
    for (double p : {edge_dropout, dark_dropout, shiny_dropout})
      a.Require(p >= 0 && p <= 1, "edge_dropout", "probabilities in [0, 1]");
    a.Require(max_range > 0, "max_range", "a positive range in m");
  }
};

// The arm's low-level controller, relative to the twin's position actuators.
struct ControllerSpec {
  double kp_scale = 0.75;          // arm actuator stiffness x this
  double kd_scale = 1.4;           // arm actuator damping x this
  double interpolation = 0.15;     // per physics step, the applied target moves this fraction of
                                   // the way to the commanded one (1 = jumps at once)
  double latency = 0.04;           // s before a new command starts to be followed
  double arm_damping_scale = 1.5;  // joint damping x this
  double arm_frictionloss_scale = 2.0;  // joint dry friction x this
  double gripper_force = 45;            // N, the fingers' force limit
  template <class A>
  void Serialize(A& a) {
    a("kp_scale", kp_scale);
    a("kd_scale", kd_scale);
    a("interpolation", interpolation);
    a("latency", latency);
    a("arm_damping_scale", arm_damping_scale);
    a("arm_frictionloss_scale", arm_frictionloss_scale);
    a("gripper_force", gripper_force);
    a.Require(kp_scale > 0 && kd_scale > 0, "kp_scale", "positive gain scales");
    a.Require(interpolation > 0 && interpolation <= 1, "interpolation", "a fraction in (0, 1]");
    a.Require(latency >= 0 && latency < 1, "latency", "a delay in [0, 1) s");
    a.Require(gripper_force > 0, "gripper_force", "a positive force in N");
  }
};

// Where the scan camera really is, against where the robot says it put it (per frame, random).
struct ScanCameraSpec {
  double position_sigma = 0.002;  // m
  double rotation_sigma = 0.003;  // rad
  template <class A>
  void Serialize(A& a) {
    a("position_sigma", position_sigma);
    a("rotation_sigma", rotation_sigma);
    a.Require(position_sigma >= 0 && rotation_sigma >= 0, "position_sigma", "non-negative errors");
  }
};

struct WorldSpec {
  std::string name;
  std::string task = "task.yaml";  // the world's own task file (scene, oracle, randomization)
  std::string robot = "panda";     // what the robot reports itself as (assets/robots/<robot>)
  ControllerSpec controller;
  DepthSensorSpec depth;
  // The camera's true mount: its reported extrinsics composed with this error (camera frame).
  std::array<double, 3> camera_offset{0, 0, 0};    // m
  std::array<double, 3> camera_rotation{0, 0, 0};  // rad, roll/pitch/yaw
  uint64_t seed = 1;                               // sensor noise stream
  // Where the scene is when the robot is switched on, and so where it is scanned: its home
  // (level 0), or a draw of `start_level` (seeded by `seed`). Evaluation perturbs around home.
  int start_level = 0;
  ScanCameraSpec scan;
  OperatorStyle operator_style;  // how the world's scripted operator types

  std::filesystem::path file;  // where it was loaded from (not serialized)
  template <class A>
  void Serialize(A& a) {
    a("name", name);
    a("task", task);
    a("robot", robot);
    a("controller", controller);
    a("depth", depth);
    a("camera_offset", camera_offset);
    a("camera_rotation", camera_rotation);
    a("seed", seed);
    a("start_level", start_level);
    a.Require(start_level >= 0 && start_level <= 3, "start_level", "a randomization level 0..3");
    a("scan", scan);
    a("operator", operator_style);
    a.Require(!name.empty(), "name", "a world name");
  }
};

// Loads `dir/world.yaml`. Throws ConfigError naming the file and field.
WorldSpec LoadWorldSpec(const std::filesystem::path& dir);

// The directory of a built-in world (assets/worlds/<name>) or `name` itself if it is a path.
std::filesystem::path ResolveWorldDir(const std::string& name);

// The proxy reality, in-process. Advances one control period per SendTargets (lockstep: the
// world's clock only moves when the robot is told to do something).
class ProxyReality : public Robot {
 public:
  explicit ProxyReality(const std::filesystem::path& world_dir);
  ~ProxyReality() override;

  // The depth sensor of a simulated twin: the ray caster's depth to the millimetre with no holes
  // (kIdeal), or with the noise calibration measured on the real camera (kCalibrated: the twin's
  // `camera.noise`, applied by sim::AddDepthNoise as the twin's rendered clouds get it; an
  // uncalibrated twin has none, so its frames are the ideal ones).
  enum class Sensor { kIdeal, kCalibrated };

  // A twin run as a robot, for the simulated episodes SAM-RL learns from: the twin task's own
  // scene, physics and position controller (commands followed at once), `sensor`, and cameras
  // exactly where they are asked to be. It reads no world file.
  static std::unique_ptr<ProxyReality> SimulatedTwin(const sim::TaskSpec& twin, Sensor sensor);

  RobotInfo Info() override;
  Observation Observe(bool with_frames) override;
  void SendTargets(const sim::JointTargets& targets) override;
  Observation Reset(const ResetRequest& request) override;
  SuccessAnswer QuerySuccess() override;
  // Renders the scene from the requested pose, off by the arm's positioning error.
  RgbdFrame Capture(const CaptureRequest& request) override;
  // The world's scripted operator, watching the hidden scene.
  OperatorInput AskOperator() override;

  // Renders one frame as the sensor would report it (exposed for tests and scans).
  RgbdFrame Frame();

  const WorldSpec& spec() const { return spec_; }
  // For graders and tests only: the hidden simulation.
  const sim::Env& hidden_env() const { return *env_; }
  // For graders only: the hidden scene now, by name: each task joint's value, each task object's
  // position, the gripper's opening and the tool's position (robot base frame, m or rad), and
  // what the arm touches ("arm_contacts": "arm body - other body/geom", robot geom group 1).
  nlohmann::json GraderState() const;
  // For graders only: each task object's pose now, by name, in the robot base frame (what
  // GraderState reports as "objects" and "object_quats").
  std::vector<std::pair<std::string, core::Pose>> ObjectPoses() const;
  // For graders and tests only: how far the last Capture's camera was from where it was asked to
  // be, in the camera's frame (the true camera is the requested pose times this).
  const core::Pose& last_capture_error() const { return last_capture_error_; }

 private:
  // `hidden_physics`: the world's controller changes the task's arm physics (a world), or the
  // task's own physics stand (a simulated twin).
  ProxyReality(WorldSpec spec, sim::TaskSpec task, bool hidden_physics);
  ProxyReality(const WorldSpec& spec, const std::filesystem::path& world_dir);
  // The sensor's depth (mm) from a rendered depth image (m, changed in place) and the geom each
  // pixel sees: the world's sensor model, after the twin's calibrated noise on a simulated twin.
  void Sense(int width, int height, const int* geom, std::vector<float>& depth, core::Rng& rng,
             std::vector<uint16_t>& depth_mm) const;
  WorldSpec spec_;
  std::shared_ptr<const sim::Task> task_;
  std::unique_ptr<sim::Env> env_;
  std::unique_ptr<sim::ServoLag> controller_;  // the arm's hidden low-level controller
  sim::Camera reported_camera_;
  std::unique_ptr<sim::RayCaster> caster_;       // at the camera's true pose
  std::unique_ptr<sim::RayCaster> scan_caster_;  // the scan camera, built for its intrinsics
  std::unique_ptr<ScriptedOperator> operator_;
  core::Rng noise_rng_;
  std::vector<float> depth_;
  std::vector<int> geom_;
  core::Rng scan_rng_;
  sim::DepthNoise twin_noise_;                // a simulated twin's calibrated sensor (else off)
  std::vector<double> twin_surface_dropout_;  // its surfaces' dropouts, by geom id
  core::Pose last_capture_error_ = core::Pose::Identity();
  double clock_ = 0;
};

// Applies the depth sensor model to a rendered depth image (metres, 0 = none) in place, given
// the geom seen at each pixel, and converts it to millimetres.
void ApplyDepthSensor(const DepthSensorSpec& sensor, const mjModel* m, int width, int height,
                      const int* geom, std::vector<float>& depth, core::Rng& rng,
                      std::vector<uint16_t>& depth_mm);

}  // namespace twinforge::reality
