// One simulated episode at a time of a task: reset with randomization, step with an action,
// observe privileged state or proprioception, check success.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "core/rng.h"
#include "core/se3.h"
#include "sim/action.h"
#include "sim/task.h"

namespace twinforge::sim {

struct StepResult {
  float reward = 0;  // sparse: 1 while the task's success predicates all hold
  bool success = false;
  bool done = false;      // horizon reached, or the simulation went unstable
  bool unstable = false;  // physics diverged (MuJoCo reset the state); the episode is void
};

// Proprioception: tool position (3) and quaternion w,x,y,z (4) in the robot base frame, finger
// joint positions (2).
constexpr int kProprioDim = 9;
// Writes proprioception from a tool pose and the two finger positions (the quaternion's sign is
// chosen so that x >= 0: the hemisphere of the tool pointing down, so that it does not flip as a
// top-down tool turns): the twin, the proxy and a real robot's recorder all fill it here.
void MakeProprio(const core::Pose& ee, double finger_left, double finger_right, float* out);

// Size of a task's privileged state (see Env::State).
inline int StateDim(const Task& task) {
  return kProprioDim + 7 * int(task.index().object_bodies.size()) +
         int(task.index().state_joints.size());
}

class ServoLag;

class Env {
 public:
  // `env_id` only names the env in messages; randomness comes from the seed given to Reset.
  explicit Env(std::shared_ptr<const Task> task, int env_id = 0);

  // Restores the nominal model and full state (qpos, qvel, act, ctrl, mocap, warm-start,
  // applied forces, time), then draws this episode's randomization for `level` (0 = nominal,
  // 1 = poses, 2 = + distractors, 3 = + disturbances) from an RNG seeded with `seed`.
  void Reset(uint64_t seed, int level);

  // Applies one action for one control period. Throws core::NumericError on NaN/inf input.
  StepResult Step(const Action& action);

  // Something that runs before every physics step and may rewrite the actuator controls: the
  // proxy reality's own low-level controller (latency, target interpolation).
  class SubstepHook {
   public:
    virtual ~SubstepHook() = default;
    virtual void BeforeSubstep(const mjModel* m, mjData* d) = 0;
  };
  // Follows joint targets for one control period (Step without the action decoding). With a
  // hook, the targets are only written to `ctrl` before the hook runs; without one, through the
  // task's servo (`control.servo`) unless it is ideal.
  StepResult StepTargets(const JointTargets& targets, SubstepHook* hook = nullptr);

  // Whether every success predicate holds now.
  bool Success() const;
  // How near the scene is to success, in [0, 1]: 1 while every predicate holds, else the product
  // of each predicate's share: a site distance's threshold / distance, an axis's upward
  // component / threshold, a joint's value / threshold, the fingers' opening / threshold (each
  // clamped to [0, 1]; a predicate with threshold <= 0 that fails shares 0). A dense return for
  // what a sparse success cannot tell apart: a peg beside its hole from one on the floor.
  double SuccessCloseness() const;

  // Privileged state: proprioception, then per object position (3) and quaternion (4), then per
  // task joint its value; all in the robot base frame. Sizes are fixed per task.
  int state_dim() const { return StateDim(*task_); }
  void State(float* out) const;
  void Proprio(float* out) const;

  // Tool pose in the robot base frame, arm joints, finger joints.
  core::Pose EePose() const;
  ArmVector ArmPositions() const;
  double FingerOpening() const;  // mean of the two finger joints (m)

  // Pose of a site in the robot base frame.
  core::Pose SitePose(int site) const;
  // Pose of a body in the robot base frame.
  core::Pose BodyPose(int body) const;

  // The twin posed, not simulated: a model of a scene observed elsewhere (SAM-RL's actor reads a
  // real scene through its twin). The arm at `q`, each finger `finger` m open, the gripper latch
  // at `closure`, velocities zero; positions recomputed (mj_kinematics).
  void PoseRobot(const ArmVector& q, double finger, double closure);
  // A body with a free joint (an object) placed at `pose`, robot base frame; velocities zero,
  // positions recomputed. A body welded to the world (a griddle) is moved in this env's model,
  // as pose randomization moves it, until the next reset. Throws core::Error naming any other
  // body (one on a joint, one inside another).
  void PlaceBody(int body, const core::Pose& pose);
  // Robot base pose in the world.
  const core::Pose& base() const { return base_; }

  const Task& task() const { return *task_; }
  const mjModel* model() const { return model_.get(); }
  const mjData* data() const { return data_.get(); }
  mjData* mutable_data() { return data_.get(); }
  // This env's model, to edit physical parameters (masses, damping, gains...) between Reset and
  // the steps; the next Reset restores the task's nominal values.
  mjModel* mutable_model() { return model_.get(); }
  const Kinematics& kinematics() const { return kinematics_; }
  const GripperState& gripper() const { return gripper_; }
  int steps() const { return steps_; }
  int level() const { return level_; }
  core::Rng& rng() { return rng_; }

 private:
  // What a success predicate measures now: the distance, joint value, upward component or
  // finger opening it compares with its threshold.
  double Measure(const TaskIndex::Predicate& p) const;

  struct ActiveDisturbance {
    int body = -1, dof = -1;
    Eigen::Vector3d force = Eigen::Vector3d::Zero();
    Eigen::Vector3d at = Eigen::Vector3d::Zero();  // point of application, body frame
    double generalized = 0;
    int start_substep = 0, end_substep = 0;
  };

  void RestoreNominalModel();
  void RandomizePoses();
  void PlaceDistractors();
  void ScheduleDisturbances();
  void RandomizePhysics();
  void ApplyForces(int substep);

  std::shared_ptr<const Task> task_;
  int env_id_;
  ModelPtr model_;                   // this env's copy: randomization edits it
  std::shared_ptr<ServoLag> servo_;  // the task's servo, unless ideal
  DataPtr data_;
  Kinematics kinematics_;
  core::Pose base_;
  core::Rng rng_;
  GripperState gripper_;
  int steps_ = 0;
  int level_ = 0;
  int substep_count_ = 0;
  std::vector<ActiveDisturbance> disturbances_;
  std::vector<Eigen::Vector2d> taken_;  // distractor placement scratch
  std::vector<int> robot_dofs_;
  int last_bad_qacc_ = 0;
};

}  // namespace twinforge::sim
