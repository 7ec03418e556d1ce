#include "app/twin_actor_cli.h"

#include "core/config.h"
#include "core/error.h"
#include "core/fs.h"
#include "learn/imitate.h"
#include "learn/torch_runtime.h"
#include "pipeline/run_directory.h"
#include "samrl/active_camera.h"
#include "sim/camera.h"

namespace twinforge::app {

void TwinActorCli::Add(CLI::App* c) {
  c->add_option("--actor", actor,
                "what acts: policy (the --policy file) or twin (SAM-RL's base actor, the twin's "
                "expert acting on object poses estimated from a frame of the robot's movable "
                "camera)")
      ->check(CLI::IsMember({"policy", "twin"}));
  c->add_option("--actor-policy", actor_policy,
                "twin actor: a state policy that chooses the actions instead of the twin's "
                "scripted expert (train imitate's; the expert still marks when to look again)")
      ->check(CLI::ExistingFile);
  c->add_option("--look", look,
                "twin actor: where its camera looks from: active (at each look, the view that "
                "shows the objects best in the twin as the actor believes it, arm included), "
                "best-fixed (one view for every look: the best with the twin as it is and the arm "
                "at rest), fixed (the task camera's pose) or q (at each look, the view a "
                "sensing-aware Q, --q, scores best: SAM-RL's active camera)")
      ->check(CLI::IsMember({"active", "best-fixed", "fixed", "q"}));
  c->add_option("--q", q, "twin actor, --look q: the Q file train samrl wrote (DIR/q.pt)")
      ->check(CLI::ExistingFile);
  c->add_option("--register-to", register_to,
                "twin actor: what the frame is registered to before the objects are fitted: "
                "robot-and-table (the arm, exact, and the upward faces of the twin's fixed "
                "geometry, which hold only the frame's height and tilt), robot (the arm alone; "
                "the default before stop 77) or fixed (all of the twin's fixed geometry: the "
                "table, panels)")
      ->check(CLI::IsMember({"robot-and-table", "robot", "fixed"}));
  c->add_option("--register-min-hold", register_min_hold,
                "twin actor: the registration moves the frame only along the directions its "
                "pairs hold by at least this much (about a count of pairs pulled along their "
                "normals; an arm seen end-on hardly holds a turn about it, a table only its "
                "height and tilt); tuned at --capture-scale 8; 0: Open3D's ICP, which slides "
                "along the others (before stop 78)")
      ->check(CLI::NonNegativeNumber);
  c->add_option("--capture-scale", capture_scale,
                "twin actor: the frame's resolution, as a multiple of the task camera's")
      ->check(CLI::Range(1, 16));
  c->add_option("--settle", settle,
                "twin actor: m; each object's fit is settled where the squared distances of its "
                "points to it, each capped at this, are least (0: the ICP's fit as it stops)")
      ->check(CLI::NonNegativeNumber);
  c->add_option("--turn-margin", turn_margin,
                "twin actor: an object seen again is fitted also at the quarter turn of its fit "
                "nearest where it was believed, and that turn is taken if it scores within this "
                "fraction of the fit's explained points (a scanned block's turns, which its fused "
                "mesh's bumps tell apart only by chance; a drawn mug turned from a seen handle "
                "scores 1.8 under); 0: the fit's own turn (before stop 93)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  c->add_option("--max-looks", relook.max_looks,
                "twin actor: looks per trial at most, the first included; the task's expert steps "
                "marked look are done again when a look finds an object moved (1: look once)")
      ->check(CLI::PositiveNumber);
  c->add_option("--moved", relook.moved,
                "twin actor: m an object must be found from where it was believed to count as "
                "moved (smaller shifts are the estimate's own scatter)")
      ->check(CLI::PositiveNumber);
  c->add_flag("--measure-reach", relook.measure_reach,
              "twin actor: once the held object is lifted, look at it in the hand, measure how "
              "far it reaches toward the sites the expert carries on it (a spatula's blade tip) "
              "and move them there");
  c->add_flag("--look-when-blocked,!--no-look-when-blocked", relook.look_when_blocked,
              "twin actor: when the expert's search begins (the carried site blocked on the way "
              "down), look again first if looks remain, and come over the hole again if it moved "
              "(default on)");
  c->add_option("--moved-when-blocked", relook.moved_when_blocked,
                "twin actor: m an object must be found from where it was believed to count as "
                "moved at the look when blocked (the belief is already known to be off there)")
      ->check(CLI::PositiveNumber);
  c->add_flag("--look-when-unseen,!--no-look-when-unseen", relook.look_when_unseen,
              "twin actor: when the first look does not see an object (hidden, out of view), "
              "look again at once if looks remain (default on)");
  measure_held = c->add_flag(
      "--measure-held,!--no-measure-held", relook.measure_held,
      "twin actor: at each look while holding an object, find it in the hand in the same "
      "frames as the rest and carry it so (the first look's frame error stays with a "
      "held object while later looks put the others right; default on with --look active "
      "or q, off with a fixed view)");
  refine = c->add_flag(
      "--refine,!--no-refine", relook.refine,
      "twin actor: an object a later look sees is believed where that look put it, even "
      "when it moved less than --moved (only a move of --moved has the step done again; "
      "default on with --look active or q, off with a fixed view, whose later looks have "
      "the arm in the way)");
  c->add_flag("--occluders,!--no-occluders", relook.occluders,
              "twin actor: tell each look what the trial's earlier frames showed that no object "
              "explains (clutter, a panel the twin has elsewhere), so an active look chooses "
              "around it (default on)");
  c->add_option("--min-points", relook.min_points,
                "twin actor: explained points (in a 640x480 frame) a fit needs for the actor to "
                "act on it; fewer (a sliver beside the arm) leave the object where it was believed")
      ->check(CLI::PositiveNumber);
  c->add_flag("--hand-clearance,!--no-hand-clearance", relook.hand_clearance,
              "twin actor: of the finger directions the expert may take alike, take the nearest "
              "whose hand keeps clear of what the frames showed that no object explains (a "
              "screen beside the hole; default on)");
  c->add_option(
       "--seen-through-points", relook.seen_through_points,
       "twin actor: a later look's fit that moves an object is ignored when its frame "
       "sees through where the fit would put it (the table where a block would stand) at "
       "this many points or more (in a 640x480 frame), and more than where it was believed; "
       "0: not checked")
      ->check(CLI::NonNegativeNumber);
  c->add_option("--look-aside", relook.look_aside,
                "twin actor: m; at the look when blocked, first take the held object this far up "
                "and toward the robot, out of the views of what it stands on, look from there "
                "and come back (once a trial; continuous tasks; default 0.08; 0: look where "
                "blocked)")
      ->check(CLI::NonNegativeNumber);
  c->add_option("--max-move", relook.max_move,
                "twin actor: m beyond which an object found is taken for a misfit (clutter taken "
                "for it), not a push, and ignored")
      ->check(CLI::PositiveNumber);
}

samrl::RelookOptions TwinActorCli::Relook() const {
  samrl::RelookOptions r = relook;
  const bool chooses = look == "active" || look == "q";
  if (!measure_held || measure_held->count() == 0) r.measure_held = chooses;
  if (!refine || refine->count() == 0) r.refine = chooses;
  return r;
}

void TwinActorCli::Check(const std::string& command, const std::string& policy) const {
  if (twin() != policy.empty())
    throw core::Error(twin() ? command + " --actor twin: takes no --policy"
                             : command + ": --policy FILE is needed (or --actor twin)");
  if (!actor_policy.empty() && !twin())
    throw core::Error(command + " --actor-policy: goes with --actor twin");
  if ((look == "q") != !q.empty())
    throw core::Error(look == "q" ? command + " --look q: needs --q FILE (train samrl's q.pt)"
                                  : command + " --q: goes with --look q");
  // The flags' values meet the checks a config file's would (--moved below --max-move, ...).
  core::Validate(Relook(), command + "'s twin actor options");
}

TwinActorOnRobot::TwinActorOnRobot(reality::Robot& robot, const sim::TaskSpec& task,
                                   const TwinActorCli& cli, uint64_t seed)
    : twin_(std::make_shared<const sim::Task>(task)) {
  if (!robot.Info().can_scan)
    throw core::Error("the twin actor: " + robot.Info().name +
                      " has no camera it can move (it does not answer capture)");
  learn::PinMathThreads(1);
  const sim::Camera camera = sim::MakeCamera(task.camera);
  const sim::CameraIntrinsics capture =
      samrl::ScaleIntrinsics(camera.intrinsics, cli.capture_scale);
  geometry_ = std::make_unique<real2sim::TwinGeometry>(task, 600);
  const samrl::ViewSearchOptions search = samrl::LookSearch();
  const core::PinholeIntrinsics search_camera = samrl::LookSearchCamera();
  const samrl::OrbitMount mount = samrl::ObjectsMount(*twin_);
  if (cli.look == "q") {
    q_ = pipeline::LoadSensingQ(cli.q, task);
    look_ = samrl::ActiveLook(robot, *geometry_, task.objects, q_.mount, q_.search, capture, search,
                              seed, samrl::QLookScore(q_.net));
  } else {
    look_ = cli.look == "fixed" ? samrl::FixedLook(robot, camera.pose, capture)
            : cli.look == "best-fixed"
                ? samrl::FixedLook(robot,
                                   samrl::BestFixedView(*geometry_, *twin_, task.objects, mount,
                                                        search_camera, search, seed),
                                   capture)
                : samrl::ActiveLook(robot, *geometry_, task.objects, mount, search_camera, capture,
                                    search, seed);
  }
  const samrl::RelookOptions relook = cli.Relook();
  samrl::PoseEstimateOptions estimate;
  estimate.register_to_robot = cli.register_to != "fixed";
  estimate.register_tops = cli.register_to == "robot-and-table";
  estimate.register_min_hold = cli.register_min_hold;
  estimate.settle = cli.settle;
  estimate.turn_margin = cli.turn_margin;
  actor_ = std::make_unique<samrl::TwinActor>(twin_, robot, look_, robot.Info().has_success_oracle,
                                              estimate, core::Pose{}, relook);
  identity_ = {{"actor", "twin"}, {"twin_hash", pipeline::TwinFingerprint(task)}};
  if (!cli.actor_policy.empty()) {
    actor_->set_policy(learn::LoadStateActor(cli.actor_policy, *twin_));
    identity_["actor_policy"] = cli.actor_policy;
    identity_["actor_policy_hash"] = core::Fingerprint().AddFile(cli.actor_policy).Hex();
  }
  header_ = identity_;
  header_["look"] = cli.look;
  if (q_.net) header_["q_hash"] = q_.hash;
  header_["settle"] = cli.settle;
  header_["turn_margin"] = cli.turn_margin;
  header_["register_to"] = cli.register_to;
  header_["register_min_hold"] = cli.register_min_hold;
  header_["max_looks"] = relook.max_looks;
  header_["moved"] = relook.moved;
  header_["max_move"] = relook.max_move;
  if (relook.measure_reach) header_["measure_reach"] = true;
  header_["look_when_blocked"] = relook.look_when_blocked;
  header_["moved_when_blocked"] = relook.moved_when_blocked;
  header_["look_when_unseen"] = relook.look_when_unseen;
  header_["occluders"] = relook.occluders;
  header_["measure_held"] = relook.measure_held;
  header_["refine"] = relook.refine;
  header_["min_points"] = relook.min_points;
  header_["hand_clearance"] = relook.hand_clearance;
  header_["seen_through_points"] = relook.seen_through_points;
  header_["look_aside"] = relook.look_aside;
  header_["capture"] = {capture.width, capture.height};
}

pipeline::ResidualBase TwinActorOnRobot::AsResidualBase() {
  samrl::TwinActor* actor = actor_.get();
  return {
      actor, [actor](uint64_t seed) { actor->Begin(seed); }, actor->feature_dim(),
      [actor](float* out) { std::copy(actor->features().begin(), actor->features().end(), out); },
      identity_};
}

nlohmann::json TwinActorOnRobot::header() const { return header_; }

}  // namespace twinforge::app
