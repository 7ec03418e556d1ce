// SAM-RL's base actor on a robot: it acts in the twin, on the twin posed as the robot reports its
// arm and with the objects where a depth frame shows them, and sends the twin's action to the
// robot. The twin's scripted expert chooses the actions; the state it reads is the estimate, never
// the scene's own (a robot has no privileged state).
//
// At a trial's first step the actor looks (a callback returns the frames: the fixed camera's, or
// a frame from a view it chose) and estimates every object's pose once. Afterwards the arm follows
// the robot's joints; an object the gripper closes on is carried with the tool from then on, as it
// sat in the hand when the fingers closed.
#pragma once

#include <functional>
#include <memory>
#include <vector>

#include "core/rng.h"
#include "reality/robot.h"
#include "reality/teleop.h"
#include "samrl/pose_estimate.h"
#include "sim/camera.h"
#include "sim/env.h"
#include "sim/expert.h"

namespace twinforge::samrl {

// The frames to estimate the objects from, given the robot's first observation.
using Look = std::function<std::vector<reality::RgbdFrame>(const reality::Observation&)>;

// One frame from a fixed pose (camera, OpenCV axes -> robot base) with the robot's movable camera.
Look FixedLook(reality::Robot& robot, const core::Pose& pose,
               const sim::CameraIntrinsics& intrinsics);

// A camera's intrinsics at `scale` times the resolution (the same field of view).
sim::CameraIntrinsics ScaleIntrinsics(sim::CameraIntrinsics k, int scale);

class TwinActor : public reality::Operator {
 public:
  // `twin`: the twin task (its objects are estimated, its expert acts). `oracle`: ask the robot
  // whether the task is done after each step (the proxy's success oracle) and stop there.
  TwinActor(std::shared_ptr<const sim::Task> twin, reality::Robot& robot, Look look, bool oracle,
            const PoseEstimateOptions& options = {}, const core::Pose& camera_correction = {});

  // Before each trial: the expert starts over and the scene is looked at again.
  void Begin(uint64_t seed);

  reality::OperatorInput Next(const reality::Observation& o) override;
  std::string name() const override { return "twin actor"; }

  // This trial's estimate (empty before its first step).
  const std::vector<ObjectPose>& estimates() const { return estimates_; }
  // The twin as the actor last saw it.
  const sim::Env& twin() const { return env_; }

 private:
  std::shared_ptr<const sim::Task> task_;
  reality::Robot& robot_;
  Look look_;
  bool oracle_;
  core::Pose camera_correction_;
  sim::Env env_;
  sim::ScriptedExpert expert_;
  ObjectPoseEstimator estimator_;
  std::vector<int> bodies_;
  std::vector<ObjectPose> estimates_;
  core::Rng rng_{0};
  bool looked_ = false;
  double closure_ = 0;
  int carried_ = -1;  // index into bodies_
  core::Pose carried_in_tool_;
};

}  // namespace twinforge::samrl
