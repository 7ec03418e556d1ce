#include "samrl/twin_actor.h"

#include <spdlog/spdlog.h>

#include "core/error.h"

namespace twinforge::samrl {

Look FixedLook(reality::Robot& robot, const core::Pose& pose,
               const sim::CameraIntrinsics& intrinsics) {
  return [&robot, pose, intrinsics](const reality::Observation&) {
    return std::vector<reality::RgbdFrame>{robot.Capture({pose, intrinsics})};
  };
}

sim::CameraIntrinsics ScaleIntrinsics(sim::CameraIntrinsics k, int scale) {
  k.width *= scale;
  k.height *= scale;
  k.fx *= scale;
  k.fy *= scale;
  k.cx = (k.cx + 0.5) * scale - 0.5;
  k.cy = (k.cy + 0.5) * scale - 0.5;
  return k;
}

TwinActor::TwinActor(std::shared_ptr<const sim::Task> twin, reality::Robot& robot, Look look,
                     bool oracle, const PoseEstimateOptions& options,
                     const core::Pose& camera_correction)
    : task_(twin),
      robot_(robot),
      look_(std::move(look)),
      oracle_(oracle),
      camera_correction_(camera_correction),
      env_(twin),
      expert_(*twin),
      estimator_(twin, twin->spec().objects, options) {
  for (const auto& name : twin->spec().objects)
    bodies_.push_back(mj_name2id(env_.model(), mjOBJ_BODY, name.c_str()));
}

void TwinActor::Begin(uint64_t seed) {
  rng_ = core::Rng(seed, 0x7a1);
  expert_.Reset();
  env_.Reset(0, 0);
  estimates_.clear();
  looked_ = false;
  closure_ = 0;
  carried_ = -1;
}

reality::OperatorInput TwinActor::Next(const reality::Observation& o) {
  reality::OperatorInput input;
  if (oracle_ && looked_ && robot_.QuerySuccess() == reality::SuccessAnswer::kSuccess) {
    input.kind = reality::OperatorInput::Kind::kDone;
    return input;
  }
  env_.PoseRobot(o.q, 0.5 * o.gripper_width, closure_);
  if (!looked_) {
    looked_ = true;
    std::vector<Eigen::Vector3d> points;
    for (const reality::RgbdFrame& frame : look_(o)) {
      const auto p =
          estimator_.Foreground(FramePoints(frame, camera_correction_), o.q, o.gripper_width);
      points.insert(points.end(), p.begin(), p.end());
    }
    estimates_ = estimator_.Estimate(points);
    for (std::size_t i = 0; i < bodies_.size(); ++i) {
      env_.PlaceBody(bodies_[i], estimates_[i].pose);
      spdlog::debug("twin actor: {} {} at ({:.3f}, {:.3f}), {} points explained, {} not",
                    estimates_[i].body, estimates_[i].seen ? "seen" : "NOT seen",
                    estimates_[i].pose.translation.x(), estimates_[i].pose.translation.y(),
                    estimates_[i].inliers, estimates_[i].outliers);
    }
  }
  const core::Pose tool = env_.EePose();
  if (carried_ >= 0) env_.PlaceBody(bodies_[carried_], tool * carried_in_tool_);
  if (expert_.finished()) {
    input.kind = reality::OperatorInput::Kind::kDone;
    return input;
  }
  input.kind = reality::OperatorInput::Kind::kAction;
  input.action = expert_.Act(env_, rng_);
  const double closure = input.action.mode == sim::ActionMode::kContinuous
                             ? double(input.action.value[6] > 0)
                         : input.action.index == 13 ? 1.0
                         : input.action.index == 12 ? 0.0
                                                    : closure_;
  if (closure > 0.5 && closure_ <= 0.5) {
    // The fingers close on the object nearest the tool, which then moves with it.
    double nearest = 0.05;
    for (std::size_t i = 0; i < bodies_.size(); ++i) {
      const double d = (env_.BodyPose(bodies_[i]).translation - tool.translation).norm();
      if (d < nearest) {
        nearest = d;
        carried_ = int(i);
      }
    }
    if (carried_ >= 0) {
      carried_in_tool_ = tool.Inverse() * env_.BodyPose(bodies_[carried_]);
      // Closing fingers centre what they close on between them (the tool's y is their axis):
      // where the tool stopped short of the estimate along it, the object was pushed along.
      carried_in_tool_.translation.y() = 0;
    }
  } else if (closure <= 0.5) {
    carried_ = -1;
  }
  closure_ = closure;
  return input;
}

}  // namespace twinforge::samrl
