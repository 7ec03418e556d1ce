// Object poses from depth, SAM-RL's state estimate: the twin's meshes of the movable objects
// registered to the points of a real frame. The points the twin's fixed geometry (the table, a
// panel, the arm at its measured joints) explains are dropped; each object is then fitted by
// planar ICP (position on the table and yaw; objects stand as the twin has them) from starts spread
// over the remaining points, and scored by the points its surface explains against the points
// inside its outline it does not (and, for an object neither on nor under another, the points
// over it: a taller box of clutter is not taken for it). The best fit is then polished (ICP'd
// again point to plane, kept if it scores better) and settled: shifted to where the squared
// distances of the points it pairs with, each capped, are least (the ICP stops short, and the
// score hardly changes over a few mm). Objects are taken best score first, each removing the
// points it explains, so two objects never claim the same points. An object with too few points
// is reported unseen (hidden behind something, or out of view) at the twin's own pose.
#pragma once

#include <Eigen/Core>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/se3.h"
#include "reality/robot.h"
#include "sim/env.h"

namespace twinforge::core {
class ThreadPool;
}  // namespace twinforge::core

namespace twinforge::samrl {

struct PoseEstimateOptions {
  double background = 0.006;  // m: points this close to the twin's fixed geometry are background
  // The frame first registered to the twin's fixed geometry (a hand camera's pose is known to a
  // few mm and mrad, enough to miss a hole): point-to-plane ICP within this reach (m), 0 = not.
  double register_reach = 0.015;
  int register_samples = 60000;
  // Registered to the robot's own geometry (exact, where a scanned table or panel is only as good
  // as its scan), else to all the fixed geometry.
  bool register_to_robot = true;
  // With the robot, also to the fixed geometry's upward faces (the table's top), which pull only
  // along their normal: they hold the frame's height and tilt where the arm alone, seen from
  // afar, does not, and cannot pull it across the table.
  bool register_tops = true;
  // The registration moves the frame only along the directions its pairs hold by at least this
  // much, about a count of pairs pulled along their normals (real2sim::AlignToSurfaces says how a
  // pair counts); 0: Open3D's ICP, which slides along the others. Seen from the hidden peg's
  // side, an arm far off held a direction by 0-2 pairs and the frame slid 5-80 mm along it. From
  // the active look's first view some direction is held by 30-100 pairs, and rightly: leaving
  // out under 100 left those frames 1-2 mm off.
  double register_min_hold = 30;
  double cell = 0.03;  // m: ICP starts at the centroids of foreground points per cell
  // m: starts, and the fits taken, only this far (in the table's plane) from the object's pose in
  // the twin. Clutter farther away adds no starts (with four boxes on the table and no bound a
  // trial took 6 min), and a fit that slides out to it is not taken.
  double search = 0.15;
  int min_cell_points = 5;  // of a start cell
  int yaw_starts = 8;       // over a whole turn
  int iterations = 25;
  // Each start's ICP steps on at most this many of the points near it, spread evenly over them
  // (0: all); the fits are scored, polished and settled on all. A scanned griddle's 464 starts
  // stepped on about 4000 points each, 25 times: 69 s of an 85 s fit of its scene.
  int start_points = 500;
  double start_reach = 0.03, reach = 0.006;  // m: correspondences kept, annealed from / to
  // The best start's fit ICP'd once more, point to plane, and taken if it scores better and has
  // not moved its outline's middle beyond start_reach. The starts step point to point, which on a
  // flat top holds each step's turn back: every point on the top pairs with the surface straight
  // under it (the scanned griddle, turned 15 deg, was found turned 4). Point to plane, a point
  // pulls only along the surface's normal, and the top pulls only up or down. Point to plane from
  // every start lost partial views the starts find (the hidden peg's block with the hand over it:
  // 2 trials of 19 lost, none won).
  bool polish = true;
  double inlier = 0.003;  // m: a point the surface explains
  int min_points = 50;    // explained points for an object to count as seen
  // A fit's score: the points it explains less this many for each point inside its outline it
  // does not, for an object alone (one on or under another, a pancake on its griddle, expects the
  // other's points there and counts each as 1). A point explained is weak evidence (any surface
  // there explains it); one where the object would leave free space is strong evidence against.
  double outlier_weight = 10;
  // m: the chosen fit is then settled where the squared distances of the points about it, each
  // capped at this, are least (0: not). The score's count of points within `inlier` hardly
  // changes over a few mm, where these do.
  double settle = 0.003;
  // Given where an object was believed (a look after the first), the quarter turn of its fit
  // nearest that belief is also polished, settled and scored, and is taken if its score is within
  // this fraction of the fit's explained points under the fit's (0: not tried), for a body not
  // found the same turned (`symmetry` 1). A scanned block's fused mesh has bumps a quarter turn
  // does not map onto themselves, so a fit's turn follows them and the sites on it (a hole) jump
  // from look to look: on the scanned occluded peg's block, at the 153 later looks that fitted it
  // a quarter or half turn from the belief, the turn nearest the belief scored -0.15 to 0.24
  // under the fit's, where the drawn mug turned from a handle in view scores 1.8 under. The
  // margin is about twice the block's worst.
  double turn_margin = 0.5;
  template <class A>
  void Serialize(A& a) {
    a("background", background);
    a("register_reach", register_reach);
    a("register_samples", register_samples);
    a("register_to_robot", register_to_robot);
    a("register_tops", register_tops);
    a("register_min_hold", register_min_hold);
    a("cell", cell);
    a("search", search);
    a("min_cell_points", min_cell_points);
    a("yaw_starts", yaw_starts);
    a("iterations", iterations);
    a("start_points", start_points);
    a("start_reach", start_reach);
    a("polish", polish);
    a("reach", reach);
    a("inlier", inlier);
    a("min_points", min_points);
    a("outlier_weight", outlier_weight);
    a("settle", settle);
    a("turn_margin", turn_margin);
    a.Require(
        background > 0 && cell > 0 && search > 0 && reach > 0 && start_reach >= reach && inlier > 0,
        "reach", "positive distances, start_reach >= reach");
    a.Require(outlier_weight >= 0, "outlier_weight", "not negative");
    a.Require(settle >= 0, "settle", "not negative, in m (0: not settled)");
    a.Require(turn_margin >= 0, "turn_margin", "not negative (0: the fit's own turn)");
    a.Require(start_points >= 0, "start_points", "not negative (0: all)");
    a.Require(yaw_starts >= 1 && iterations >= 1 && min_points >= 1, "yaw_starts",
              "at least one start, iteration and point");
  }
};

struct ObjectPose {
  std::string body;
  core::Pose pose;    // robot base frame (the twin's own pose when not seen)
  bool seen = false;  // enough points explained
  int inliers = 0;    // points within options.inlier of the surface
  int outliers = 0;   // points inside its outline farther than options.reach
  double rms = 0;     // m, over the inliers
  int starts = 0;     // the ICP's starts fitted (cells of points, each at its yaws)
  // The fit's score: inliers less the outliers weighed as options.outlier_weight says. Under 0,
  // more of the frame speaks against the fit than for it (an object hidden, fitted to what
  // stands in front of it).
  double score = 0;
};

// A depth frame's points in the robot base frame: its reported extrinsics composed with
// `correction` (the camera's calibration), pixels without a return skipped.
std::vector<Eigen::Vector3d> FramePoints(const reality::RgbdFrame& frame,
                                         const core::Pose& correction = core::Pose::Identity());

class ObjectPoseEstimator {
 public:
  // The twin task's bodies to estimate (its movable objects). Throws core::Error naming a body the
  // twin does not have or one with no visible geometry. `threads` fit the starts of an object
  // (0: the machine's cores); the estimates do not depend on it.
  ObjectPoseEstimator(std::shared_ptr<const sim::Task> twin, const std::vector<std::string>& bodies,
                      const PoseEstimateOptions& options = {}, int threads = 0);
  ~ObjectPoseEstimator();

  // The points of a frame the twin's fixed geometry does not explain, inside the task's
  // workspace, the arm at `q` with the fingers `gripper_width` apart (the arm is in the frame
  // too); the frame registered to that geometry first, if the options say so (`correction`: the
  // rigid motion applied to the points). `held`: one of the bodies (an index into them) that the
  // gripper holds, at `held_pose`: its points count as the arm's (-1: none). `held_points`, if
  // given, gets the registered frame's points within `held_reach` of the held object that the
  // rest of the fixed geometry and the arm does not explain: the held object as the frame shows
  // it, wherever it sits in the hand.
  std::vector<Eigen::Vector3d> Foreground(const std::vector<Eigen::Vector3d>& points,
                                          const sim::ArmVector& q, double gripper_width,
                                          core::Pose* correction = nullptr, int held = -1,
                                          const core::Pose& held_pose = core::Pose::Identity(),
                                          std::vector<Eigen::Vector3d>* held_points = nullptr,
                                          double held_reach = 0.01);

  // Every body's pose from foreground points, in the order the bodies were given; a body whose
  // `skip` entry is true is not fitted (reported unseen, at the twin's own pose). A body with a
  // `references` entry (where it was believed) may be found at the quarter turn of its fit
  // nearest it (options.turn_margin).
  std::vector<ObjectPose> Estimate(
      const std::vector<Eigen::Vector3d>& foreground, const std::vector<bool>& skip = {},
      const std::vector<std::optional<core::Pose>>& references = {}) const;

  // Body i at `pose` shifted in the table's plane, by at most `bound` (m) along each axis, to
  // where the squared distances of `points` to its surface, each capped at options.settle (3 mm
  // if 0), are least (the settle of every fit; also for an object in the hand).
  core::Pose Settled(int i, const core::Pose& pose, const std::vector<Eigen::Vector3d>& points,
                     double bound) const;

  // Of `points` (robot base frame) seen from `camera`, how many lie farther along their rays than
  // body i's surface at `pose` would be, by more than `margin` (m): the camera saw through where
  // the object would stand. That is free space a fit's score does not read: the table seen
  // behind it is not in the foreground.
  int SeenThrough(int i, const core::Pose& pose, const Eigen::Vector3d& camera,
                  const std::vector<Eigen::Vector3d>& points, double margin) const;

  // The twin's own pose of body i.
  const core::Pose& nominal(int i) const;
  // How many turns about its vertical axis leave body i looking the same (4: a square peg, 2, or
  // 1): its vertices turned by a quarter (or a half) turn all lie on its surface, within 1 mm.
  // 0: any turn does, to a tenth of its radius (a scanned pancake: round, its yaw not seen).
  int symmetry(int i) const;
  // Of the poses of body i that look alike (`pose` turned by its symmetry), the one whose
  // rotation is nearest `reference`'s, by default the twin's own. A fit cannot tell them apart;
  // a learned actor, trained on poses near the twin's own, needs the one it has seen, and an
  // object seen again is the one believed before, not a quarter turn of it. A round body takes
  // the reference's rotation, turned about its own axis: its sites (a pancake's near edge) are
  // where the twin has them round it, not where a fit's arbitrary turn put them.
  core::Pose NearestLookAlike(int i, const core::Pose& pose) const;
  core::Pose NearestLookAlike(int i, const core::Pose& pose, const core::Pose& reference) const;
  // The twin's own pose of body i, carried as the object it stands on in the twin (a pancake on
  // its griddle) stands at `poses` (one a body) against the twin's own: a round body's reference
  // turn, where its sites lie as the twin has them round what carries it.
  core::Pose NominalOn(int i, const std::vector<core::Pose>& poses) const;

 private:
  struct Model;
  ObjectPose Fit(const Model& model, const std::vector<Eigen::Vector3d>& points,
                 const core::Pose* reference) const;
  PoseEstimateOptions options_;
  std::shared_ptr<const sim::Task> twin_;
  sim::Env env_;
  std::vector<std::unique_ptr<Model>> models_;
  std::unique_ptr<core::ThreadPool> pool_;
  std::vector<int> object_geoms_;  // geoms of the estimated bodies (not background)
};

}  // namespace twinforge::samrl
