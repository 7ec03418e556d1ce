// A robot as a file: its MJCF, which joints the controller drives, its tool frame and home pose.
// Kinematics runs on a private copy of the robot model alone, so the same code serves the twin,
// the proxy reality and a real arm (where only joint positions are known).
#pragma once

#include <Eigen/Core>
#include <array>
#include <filesystem>
#include <string>
#include <vector>

#include "core/se3.h"
#include "sim/model.h"

namespace twinforge::sim {

constexpr int kArmDof = 7;
using ArmVector = Eigen::Matrix<double, kArmDof, 1>;

struct RobotSpec {
  std::string mjcf = "panda.xml";  // relative to the robot file
  std::vector<std::string> arm_joints;
  std::vector<std::string> finger_joints;
  std::string ee_site = "ee";
  std::vector<double> home;
  double gripper_open = 0.04;
  double gripper_closed = 0.0;

  std::filesystem::path file;  // where it was loaded from (not serialized)

  template <class A>
  void Serialize(A& a) {
    a("mjcf", mjcf);
    a("arm_joints", arm_joints);
    a("finger_joints", finger_joints);
    a("ee_site", ee_site);
    a("home", home);
    a("gripper_open", gripper_open);
    a("gripper_closed", gripper_closed);
    a.Require(arm_joints.size() == kArmDof, "arm_joints", "7 joint names");
    a.Require(finger_joints.size() == 2, "finger_joints", "2 joint names");
    a.Require(home.size() == kArmDof, "home", "7 joint positions");
    a.Require(gripper_open > gripper_closed, "gripper_open", "a value above gripper_closed");
  }
  std::filesystem::path mjcf_path() const { return file.parent_path() / mjcf; }
};

// Loads a robot description (YAML). Throws ConfigError naming the file and field.
RobotSpec LoadRobotSpec(const std::filesystem::path& path);

// The default robot shipped in assets/robots/panda/robot.yaml.
std::filesystem::path DefaultRobotPath();

// Indices of the robot's parts inside some mjModel (the robot alone, or a whole task scene).
struct RobotIndex {
  std::array<int, kArmDof> arm_qpos{}, arm_dof{}, arm_actuator{};
  std::array<int, 2> finger_qpos{}, finger_dof{}, finger_actuator{};
  int ee_site = -1;
  ArmVector lower, upper;  // joint limits

  // Resolves names; throws ConfigError naming the missing joint/actuator/site.
  static RobotIndex Resolve(const mjModel* m, const RobotSpec& spec);
};

struct IkOptions {
  double damping = 0.05;         // DLS lambda
  int iterations = 4;            // Newton steps on the kinematic model
  double limit_margin = 0.02;    // rad kept clear of joint limits
  double rotation_weight = 0.5;  // metres per radian when mixing errors
};

// Forward and differential inverse kinematics of the arm, in the robot base frame.
class Kinematics {
 public:
  explicit Kinematics(const RobotSpec& spec);

  // Tool-centre-point pose for arm joint positions q.
  core::Pose EePose(const ArmVector& q) const;
  // 6x7 Jacobian (linear; angular) of the tool centre point at q.
  Eigen::Matrix<double, 6, kArmDof> Jacobian(const ArmVector& q) const;
  // Joint positions near q whose tool pose approaches `target` (damped least squares, clamped to
  // joint limits). Never returns NaN: on a singular step it keeps the last good iterate.
  ArmVector SolveIk(const ArmVector& q, const core::Pose& target,
                    const IkOptions& options = {}) const;

  const RobotSpec& spec() const { return spec_; }
  const RobotIndex& index() const { return index_; }
  ArmVector home() const { return ArmVector(spec_.home.data()); }

 private:
  void SetArm(const ArmVector& q) const;
  RobotSpec spec_;
  ModelPtr model_;
  DataPtr data_;  // scratch; Kinematics is not shared between threads
  RobotIndex index_;
  mutable std::vector<double> jacp_, jacr_;  // scratch Jacobians (3 x nv)
};

}  // namespace twinforge::sim
