// Tasks are data: a YAML file names the scene, the robot, what success means, the horizon, how
// each randomization level perturbs the scene, and a scripted expert as a list of waypoints.
// No C++ branches on object names: everything below refers to MJCF names from the file.
#pragma once

#include <array>
#include <cmath>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "sim/action.h"
#include "sim/mjcf.h"
#include "sim/model.h"
#include "sim/robot.h"

namespace twinforge::sim {

using Range = std::array<double, 2>;  // [min, max]

enum class PredicateType { kSiteDistanceBelow, kJointAbove, kAxisUpright, kGripperReleased };

// One success condition; the task succeeds while all hold.
struct SuccessPredicate {
  PredicateType type = PredicateType::kJointAbove;
  std::string site_a, site_b;  // site_distance_below
  std::string joint;           // joint_above
  std::string body;            // axis_upright: the body whose local `axis` must point up
  std::array<double, 3> axis{0, 0, 1};
  double threshold = 0.0;  // distance (m), joint value, min |axis . z|, min finger opening
  template <class A>
  void Serialize(A& a) {
    a.Enum("type", type,
           {{"site_distance_below", PredicateType::kSiteDistanceBelow},
            {"joint_above", PredicateType::kJointAbove},
            {"axis_upright", PredicateType::kAxisUpright},
            {"gripper_released", PredicateType::kGripperReleased}});
    a("site_a", site_a);
    a("site_b", site_b);
    a("joint", joint);
    a("body", body);
    a("axis", axis);
    a("threshold", threshold);
    a.Require(type != PredicateType::kSiteDistanceBelow || (!site_a.empty() && !site_b.empty()),
              "site_a", "two site names (site_a, site_b) for site_distance_below");
    a.Require(type != PredicateType::kJointAbove || !joint.empty(), "joint",
              "a joint name for joint_above");
    a.Require(type != PredicateType::kAxisUpright || !body.empty(), "body",
              "a body name for axis_upright");
  }
};

// Level >= 1: bodies moved together by one offset and one yaw about the first body.
struct PoseGroup {
  std::vector<std::string> bodies;
  Range x{0, 0}, y{0, 0}, z{0, 0}, yaw{0, 0};
  template <class A>
  void Serialize(A& a) {
    a("bodies", bodies);
    a("x", x);
    a("y", y);
    a("z", z);
    a("yaw", yaw);
    a.Require(!bodies.empty(), "bodies", "at least one body name");
    a.Require(x[0] <= x[1] && y[0] <= y[1] && z[0] <= z[1] && yaw[0] <= yaw[1], "x",
              "ranges written [min, max]");
  }
};

// Level >= 2: static clutter boxes placed on the table around the task objects.
struct DistractorSpec {
  int max_count = 4;
  std::array<int, 2> count{1, 4};
  Range size{0.015, 0.045};  // half-extent of each box (m)
  std::array<double, 3> region_min{0.2, -0.45, 0.0};
  std::array<double, 3> region_max{0.75, 0.45, 0.0};
  double clearance = 0.08;  // min distance (xy) to any object body
  template <class A>
  void Serialize(A& a) {
    a("max_count", max_count);
    a("count", count);
    a("size", size);
    a("region_min", region_min);
    a("region_max", region_max);
    a("clearance", clearance);
    a.Require(count[0] >= 0 && count[0] <= count[1] && count[1] <= max_count, "count",
              "[min, max] with 0 <= min <= max <= max_count");
  }
};

// Level >= 3: a push during the episode, on a free body (a force in a random horizontal
// direction) or on a joint (a generalised force, e.g. a drawer pushed back).
struct DisturbanceSpec {
  std::string body;
  std::string joint;
  Range force{5, 10};      // N (body) or N / Nm (joint; the sign is kept)
  double duration = 0.3;   // s
  Range window{0.2, 0.6};  // when it starts, as a fraction of the horizon
  double probability = 1.0;
  std::array<double, 3> at{0, 0, 0};  // body: where the push lands, in the body frame (m)
  template <class A>
  void Serialize(A& a) {
    a("body", body);
    a("joint", joint);
    a("force", force);
    a("duration", duration);
    a("window", window);
    a("probability", probability);
    a("at", at);
    a.Require(body.empty() != joint.empty(), "body", "exactly one of body or joint");
  }
};

// Optional physics randomization, as scale factors on the nominal model, one draw of each per
// episode: `friction` on the scene's geoms' sliding friction, `mass` on its bodies' masses (and
// inertias), `damping` and `frictionloss` on its joints' damping and dry friction,
// `actuator_gain` on every actuator's stiffness, `grip_force` on the fingers' force limit. The
// robot's own links, joints and geoms keep their values (sysid measures those).
struct PhysicsRandomization {
  int from_level = 4;  // applied at this level and above (4 = never)
  Range friction{1, 1}, mass{1, 1}, damping{1, 1}, actuator_gain{1, 1};
  Range frictionloss{1, 1}, grip_force{1, 1};
  bool enabled() const { return from_level <= 3; }
  template <class A>
  void Serialize(A& a) {
    a("from_level", from_level);
    a("friction", friction);
    a("mass", mass);
    a("damping", damping);
    a("actuator_gain", actuator_gain);
    a("frictionloss", frictionloss);
    a("grip_force", grip_force);
    a.Require(from_level >= 0 && from_level <= 4, "from_level",
              "a randomization level 0..3, or 4 for never");
    const std::pair<const char*, const Range*> ranges[] = {
        {"friction", &friction},         {"mass", &mass},
        {"damping", &damping},           {"actuator_gain", &actuator_gain},
        {"frictionloss", &frictionloss}, {"grip_force", &grip_force}};
    for (const auto& [key, r] : ranges)
      a.Require((*r)[0] > 0 && (*r)[0] <= (*r)[1], key, "a scale range [min, max], 0 < min <= max");
  }
};

struct RandomizationSpec {
  std::vector<PoseGroup> groups;
  double robot_joint_noise = 0.0;  // rad added to each home joint, level >= 1
  DistractorSpec distractors;
  std::vector<DisturbanceSpec> disturbances;
  PhysicsRandomization physics;
  template <class A>
  void Serialize(A& a) {
    a("groups", groups);
    a("robot_joint_noise", robot_joint_noise);
    a("distractors", distractors);
    a("disturbances", disturbances);
    a("physics", physics);
  }
};

enum class ExpertStepType { kMove, kGrip, kDrive };
enum class GripCommand { kKeep, kOpen, kClose };

// One waypoint of the scripted expert. Poses are given in the yaw frame of `site` (z up, x along
// the site's x projected on the table): the tool centre goes to `offset`, the gripper's approach
// axis (tool z) along `approach` and its finger-opening axis (tool y) along +-`fingers`.
struct ExpertStep {
  ExpertStepType type = ExpertStepType::kMove;
  std::string site;                          // anchor ("" = world)
  std::array<double, 3> offset{0, 0, 0};     // m, in the anchor's yaw frame
  std::array<double, 3> approach{0, 0, -1};  // tool z in the anchor frame (default: down)
  std::array<double, 3> fingers{0, 1, 0};    // tool y in the anchor frame (sign is free)
  // move: how many finger directions serve alike, `fingers` turned about `approach` by every
  // 1/symmetry of a turn: 2 (a parallel gripper: +-fingers) or, for a square peg or hole, 4. The
  // one nearest the tool where the step starts is kept for the step, so the wrist turns at most
  // half of 1/symmetry of a turn.
  int symmetry = 2;
  bool world_orientation = false;  // orientation in the base frame, not the anchor's
  // move: a site on the held object; the step brings that site, not the tool, to the target
  // (an anchor on the held object itself is taken where the step starts).
  std::string carry;
  bool keep_orientation = false;  // move: hold the tool orientation the step starts with
  // move: take the anchor where the step starts, not where it is now (an anchor on an object
  // the step itself moves: the far edge of a pancake the blade is lifting).
  bool freeze_anchor = false;
  double speed = 0;  // move, continuous actions: m per step at most (0 = limit)
  GripCommand gripper = GripCommand::kKeep;
  std::string joint;                 // drive: the joint to move
  double to = 0.0;                   // drive: target joint value
  double lead = 0.03;                // drive: how far ahead of the grasp to aim
  int hold = 4;                      // grip: control steps to wait
  double tolerance = 0.012;          // m, move: position tolerance
  double rotation_tolerance = 0.12;  // rad
  int max_steps = 60;                // give up on the step after this many control steps
  // move, discrete actions: at the limit of the 3 cm grid, keep going with combined turns and
  // moves (slower; for a grasp that needs a few mm, made where there is room to turn).
  bool refine = false;
  // move: a robot's twin actor (SAM-RL's base actor, acting on estimated object poses) looks at
  // the scene again when this step is done; an object it does not hold found moved, it does the
  // step again toward where the object is now. The sim's expert reads the state and ignores it.
  bool look = false;
  // move, with a carried site: a search for a hole the estimate missed by a few mm. When the
  // carried site stops going down (a peg standing on the block's top beside its hole), the target
  // walks a spiral in the anchor's plane out to this radius (m), pressing down gently, until the
  // site drops (0: no search).
  double search = 0;
  template <class A>
  void Serialize(A& a) {
    a.Enum("type", type,
           {{"move", ExpertStepType::kMove},
            {"grip", ExpertStepType::kGrip},
            {"drive", ExpertStepType::kDrive}});
    a("site", site);
    a("offset", offset);
    a("approach", approach);
    a("fingers", fingers);
    a("symmetry", symmetry);
    a.Require(symmetry >= 2 && symmetry % 2 == 0, "symmetry",
              "an even number of finger directions (2: +-fingers; 4: also across)");
    a("world_orientation", world_orientation);
    a("carry", carry);
    a("keep_orientation", keep_orientation);
    a("freeze_anchor", freeze_anchor);
    a("speed", speed);
    a.Require(speed >= 0, "speed", "a non-negative step length in m");
    a.Enum("gripper", gripper,
           {{"keep", GripCommand::kKeep},
            {"open", GripCommand::kOpen},
            {"close", GripCommand::kClose}});
    a("joint", joint);
    a("to", to);
    a("lead", lead);
    a("hold", hold);
    a("tolerance", tolerance);
    a("rotation_tolerance", rotation_tolerance);
    a("max_steps", max_steps);
    a("refine", refine);
    a("look", look);
    a("search", search);
    a.Require(search >= 0 && (search == 0 || !carry.empty()), "search",
              "a non-negative radius in m, on a step that carries a site");
    a.Require(type != ExpertStepType::kDrive || !joint.empty(), "joint",
              "a joint name for a drive step");
    a.Require(type != ExpertStepType::kGrip || gripper != GripCommand::kKeep, "gripper",
              "open or close for a grip step");
    a.Require(max_steps > 0, "max_steps", "a positive number of control steps");
    const Eigen::Vector3d z(approach.data()), y(fingers.data());
    a.Require(
        z.norm() > 1e-6 && y.norm() > 1e-6 && z.normalized().cross(y.normalized()).norm() > 0.5,
        "fingers", "a direction well away from approach (at least 30 deg)");
  }
};

struct ExpertSpec {
  std::vector<ExpertStep> steps;
  template <class A>
  void Serialize(A& a) {
    a("steps", steps);
  }
};

// A depth sensor's noise: sigma = sigma0 + sigma_z2 * z^2 (m) on each return, returns lost at
// depth edges (a 4-neighbour `edge_jump` nearer or farther, or with no return) with probability
// `edge_dropout` and elsewhere with `dropout`, and depth reported in steps of `quantization`.
// `twinforge calibrate` measures it on the real camera's frames against the twin.
// A surface the depth sensor loses more returns on than the rest of the scene (shiny metal,
// dark plastic): a return there that survived the other dropouts is lost with this probability.
struct SurfaceDropout {
  std::string geom;  // the geom's name in the scene
  double dropout = 0.0;
  template <class A>
  void Serialize(A& a) {
    a("geom", geom);
    a("dropout", dropout);
    a.Require(!geom.empty(), "geom", "a geom name");
    a.Require(dropout >= 0 && dropout <= 1, "dropout", "a probability in [0, 1]");
  }
};

struct DepthNoise {
  double sigma0 = 0.0;
  double sigma_z2 = 0.0;
  double edge_jump = 0.02;
  double edge_dropout = 0.0;
  double dropout = 0.0;
  double quantization = 0.0;
  std::vector<SurfaceDropout> surfaces;
  bool off() const {
    return sigma0 <= 0 && sigma_z2 <= 0 && edge_dropout <= 0 && dropout <= 0 && quantization <= 0 &&
           surfaces.empty();
  }
  template <class A>
  void Serialize(A& a) {
    a("sigma0", sigma0);
    a("sigma_z2", sigma_z2);
    a("edge_jump", edge_jump);
    a("edge_dropout", edge_dropout);
    a("dropout", dropout);
    a("quantization", quantization);
    a("surfaces", surfaces);
    a.Require(sigma0 >= 0 && sigma_z2 >= 0 && quantization >= 0, "sigma0",
              "non-negative noise and quantization (m)");
    a.Require(edge_dropout >= 0 && edge_dropout <= 1 && dropout >= 0 && dropout <= 1, "dropout",
              "probabilities in [0, 1]");
    a.Require(edge_jump > 0, "edge_jump", "a positive depth step (m)");
  }
};

struct CameraSpec {
  std::string name = "front";
  std::array<double, 3> position{1.1, 0.0, 0.75};  // robot base frame
  std::array<double, 3> look_at{0.5, 0.0, 0.1};
  double fovy_deg = 58.0;
  int width = 80, height = 60;
  // Where the camera really is against position/look_at, from `twinforge calibrate`: rotation
  // vector then translation (rad, m) in the camera's own frame (OpenCV axes). A real frame's
  // reported extrinsics are corrected by the same (reality::FrameCloud).
  std::array<double, 6> correction{0, 0, 0, 0, 0, 0};
  DepthNoise noise;  // the real sensor's, as calibration measured it (none by default)
  // The movable camera's mount (SAM-RL's camera arm; samrl::ObjectsMount): 0.6 m from the task's
  // objects, at these azimuths ([min, max] rad about +z, from +x; the robot stands at -x) and
  // elevations (rad above the table). Unset, ObjectsMount's defaults (all round but behind the
  // robot, 0.8-1.3 rad up). Optional so that a task that does not set them is written, and
  // fingerprinted, as before they existed: a run made then keeps its stages.
  std::optional<std::array<double, 2>> mount_azimuth, mount_elevation;
  template <class A>
  void Serialize(A& a) {
    a("name", name);
    a("noise", noise);
    a("position", position);
    a("look_at", look_at);
    a("fovy_deg", fovy_deg);
    a("width", width);
    a("height", height);
    a("correction", correction);
    a("mount_azimuth", mount_azimuth);
    a("mount_elevation", mount_elevation);
    a.Require(width > 0 && height > 0, "width", "a positive image size");
    a.Require(!mount_azimuth ||
                  (-M_PI <= (*mount_azimuth)[0] && (*mount_azimuth)[0] <= (*mount_azimuth)[1] &&
                   (*mount_azimuth)[1] <= M_PI),
              "mount_azimuth", "[min, max] rad within [-pi, pi]");
    a.Require(!mount_elevation ||
                  (0 < (*mount_elevation)[0] && (*mount_elevation)[0] <= (*mount_elevation)[1] &&
                   (*mount_elevation)[1] < M_PI / 2),
              "mount_elevation", "[min, max] rad within (0, pi/2)");
    a.Require(fovy_deg > 1 && fovy_deg < 170, "fovy_deg", "a field of view in (1, 170) deg");
  }
};

// How a twin rebuilt from a scan of the task's scene (`twin build --task`) gets the names this
// file refers to: which scanned segment is which body, the joint a two-state scan finds, and
// where each site goes. The task's author writes it once, as a person would in the twin editor;
// it holds no geometry beyond rough sizes, and what a person would type from a part's drawing
// (a hole's size). See docs/twin.md.
struct TwinPartRecipe {
  std::string name;                     // the body name the task uses
  std::array<double, 3> size{0, 0, 0};  // rough extent (m): the two horizontal ones, then height
  bool fixed = false;                   // welded to the world (furniture), else a free body
  double mass = 0;                      // kg (0: the build's guess)
  double friction = 0;                  // (0: the build's default)
  // What the part collides as: "scan" (boxes over its scanned surface), or a solid fitted to the
  // scan, "box" or "cylinder" (upright), where the scan's few mm of blur matter: a peg in a
  // hole, a mug's walls between the fingers. Or "drawing": a known object (a tool) the scan
  // cannot rebuild, a spatula's blade flat on the table; its solids, mass and sites come from
  // `drawing` and only its pose from the scan (real2sim/drawing.h).
  std::string shape = "scan";
  // With shape "drawing": the MJCF file (relative to the task file) with a body named `name`
  // whose frame is upright as the object rests.
  std::string drawing;
  // A part that stands on another (a pancake on a griddle) is in its segment of the scan: it is
  // carved out of part `on` (shape "scan"), as what stands on its top, wider than half its own
  // smaller horizontal `size` (a lip or rim is not). Empty: it has its own segment.
  std::string on;
  // A box hole down from the middle of a "box" part's top (x, y in its face frame, depth; a
  // depth of 0 or past the bottom goes through), m. Zero: none. The scan cannot show a hole's
  // clearance to a mm; this is the drawing's size.
  std::array<double, 3> hole{0, 0, 0};
  template <class A>
  void Serialize(A& a) {
    a("name", name);
    a("size", size);
    a("fixed", fixed);
    a("mass", mass);
    a("friction", friction);
    a("shape", shape);
    a("hole", hole);
    a("drawing", drawing);
    a("on", on);
    a.Require(shape == "scan" || shape == "box" || shape == "cylinder" || shape == "drawing",
              "shape", "\"scan\", \"box\", \"cylinder\" or \"drawing\"");
    a.Require((shape == "drawing") == !drawing.empty(), "drawing",
              "an MJCF file with the part's body, given with shape \"drawing\" (and only then)");
    a.Require(hole[0] == 0 || (shape == "box" && hole[0] > 0 && hole[1] > 0 && hole[2] >= 0),
              "hole", "[x, y, depth] in m, on a part of shape \"box\"");
    a.Require(!name.empty(), "name", "a body name");
    a.Require(size[0] > 0 && size[1] > 0 && size[2] > 0, "size",
              "three positive extents in m (horizontal, horizontal, height)");
    a.Require(mass >= 0 && friction >= 0, "mass", "a non-negative mass and friction");
  }
};

// A part that moves between the two scans: cut out of `parent` and joined to it.
struct TwinJointRecipe {
  std::string name;                // the joint name the task uses
  std::string part;                // the body name of the moving part
  std::string parent;              // a part of `parts`
  std::string type = "prismatic";  // prismatic | revolute (checked against the estimate)
  double damping = 1, frictionloss = 0;
  double mass = 0.5;  // kg of the moving part
  template <class A>
  void Serialize(A& a) {
    a("name", name);
    a("part", part);
    a("parent", parent);
    a("type", type);
    a("damping", damping);
    a("frictionloss", frictionloss);
    a("mass", mass);
    a.Require(!name.empty() && !part.empty() && !parent.empty(), "name",
              "a joint name, its moving part and its parent");
    a.Require(type == "prismatic" || type == "revolute", "type", "prismatic or revolute");
    a.Require(mass > 0, "mass", "a positive mass in kg");
  }
};

// A site on a part: at a point of the part's bounds (`box`: -1..1 per axis of the base frame,
// e.g. [0, 0, 1] the middle of its top), or, with `handle`, on what sticks out of it (a moving
// part's handle: the extreme of its surface along the way it opens; a free part's: the extreme
// horizontally from its core), `inset` m back in; then moved by `offset` m. The site's x axis
// (which the expert's steps are written in) points along the handle's direction, or along the
// part's faces (its upright frame), turned by `turn_deg` about +z.
struct TwinSiteRecipe {
  std::string name, part;
  bool handle = false;
  std::array<double, 3> box{0, 0, 0};
  double inset = 0;
  std::array<double, 3> offset{0, 0, 0};
  double turn_deg = 0;
  // A solid box (x, y, z sizes in the site's frame, m) added at the site, its centre moved by
  // `grip_offset` (site frame): a handle the scan shows poorly, as a person would add one in the
  // editor. Zero: none.
  std::array<double, 3> grip_box{0, 0, 0};
  std::array<double, 3> grip_offset{0, 0, 0};
  // The scanned surface cut away around the site first (a subtract cut: sizes, and the centre's
  // offset from the site, in the site's frame, m): what is left of a half-lost handle would
  // only get in the fingers' way. Zero size: nothing cut.
  std::array<double, 3> clear_box{0, 0, 0};
  std::array<double, 3> clear_offset{0, 0, 0};
  template <class A>
  void Serialize(A& a) {
    a("name", name);
    a("part", part);
    a("handle", handle);
    a("box", box);
    a("inset", inset);
    a("offset", offset);
    a("turn_deg", turn_deg);
    a("grip_box", grip_box);
    a("grip_offset", grip_offset);
    a("clear_box", clear_box);
    a("clear_offset", clear_offset);
    a.Require(!name.empty() && !part.empty(), "name", "a site name and its part");
  }
};

struct TwinRecipe {
  std::vector<TwinPartRecipe> parts;
  std::vector<TwinJointRecipe> joints;
  std::vector<TwinSiteRecipe> sites;
  template <class A>
  void Serialize(A& a) {
    a("parts", parts);
    a("joints", joints);
    a("sites", sites);
  }
};

struct WorkspaceSpec {
  std::array<double, 3> min{-0.3, -0.6, 0.02};
  std::array<double, 3> max{0.9, 0.6, 1.0};
  template <class A>
  void Serialize(A& a) {
    a("min", min);
    a("max", max);
  }
};

// The robot's servo as a real arm's differs from ideal position actuators (sim/servo_lag.h):
// commands take effect after a latency and the target moves toward them by a fraction per
// physics step. The default is the ideal servo.
struct ServoLagSpec {
  double interpolation = 1.0;  // per physics step, the applied target moves this fraction of the
                               // way to the commanded one (1 = jumps at once)
  double latency = 0.0;        // s before a new command starts to be followed
  bool ideal() const { return interpolation == 1.0 && latency == 0.0; }
  template <class A>
  void Serialize(A& a) {
    a("interpolation", interpolation);
    a("latency", latency);
    a.Require(interpolation > 0 && interpolation <= 1, "interpolation", "a fraction in (0, 1]");
    a.Require(latency >= 0 && latency < 1, "latency", "a delay in [0, 1) s");
  }
};

// The arm's actuator stiffness (kp) and damping (kd), and its joints' damping and dry friction,
// each as a multiple of the robot model's.
struct ArmPhysicsScales {
  double kp = 1, kd = 1, damping = 1, frictionloss = 1;
  template <class A>
  void Serialize(A& a) {
    a("kp", kp);
    a("kd", kd);
    a("damping", damping);
    a("frictionloss", frictionloss);
    a.Require(kp > 0, "kp", "a positive scale");
    a.Require(kd > 0, "kd", "a positive scale");
    a.Require(damping > 0, "damping", "a positive scale");
    a.Require(frictionloss > 0, "frictionloss", "a positive scale");
  }
};

struct ControlSpec {
  ActionMode action = ActionMode::kDiscrete;
  ActionLimits limits;
  int substeps = 20;        // physics steps per control step
  double timestep = 0.005;  // s per physics step (10 Hz control by default)
  // The robot's low-level controller as identified on the real arm (`twinforge sysid`).
  ServoLagSpec servo;
  ArmPhysicsScales arm_scales;
  double grip_force = 0;  // the fingers' force limit (N); 0: the robot model's own
  template <class A>
  void Serialize(A& a) {
    a.Enum("action", action,
           {{"discrete", ActionMode::kDiscrete}, {"continuous", ActionMode::kContinuous}});
    a("limits", limits);
    a("substeps", substeps);
    a("timestep", timestep);
    a("servo", servo);
    a("arm_scales", arm_scales);
    a("grip_force", grip_force);
    a.Require(grip_force >= 0, "grip_force", "a force in N (0: the robot model's own)");
    a.Require(substeps > 0, "substeps", "a positive integer");
    a.Require(timestep > 0 && timestep <= 0.02, "timestep", "a step in (0, 0.02] s");
    a.Require(servo.latency < substeps * timestep, "servo",
              "a latency shorter than one control period (substeps x timestep)");
  }
};

struct TaskSpec {
  std::string name;
  std::string scene;  // MJCF, relative to the task file
  std::string robot;  // robot YAML, relative to the task file ("" = default)
  std::array<double, 3> robot_position{0, 0, 0};
  double robot_yaw = 0.0;
  ControlSpec control;
  int horizon = 100;                 // control steps
  std::vector<std::string> objects;  // bodies whose pose enters the privileged state
  std::vector<std::string> joints;   // joints whose value enters the privileged state
  std::vector<SuccessPredicate> success;
  RandomizationSpec randomization;
  ExpertSpec expert;
  CameraSpec camera;
  WorkspaceSpec workspace;
  TwinRecipe twin;

  std::filesystem::path file;  // where it was loaded from (not serialized)

  template <class A>
  void Serialize(A& a) {
    a("name", name);
    a("scene", scene);
    a("robot", robot);
    a("robot_position", robot_position);
    a("robot_yaw", robot_yaw);
    a("control", control);
    a("horizon", horizon);
    a("objects", objects);
    a("joints", joints);
    a("success", success);
    a("randomization", randomization);
    a("expert", expert);
    a("camera", camera);
    a("workspace", workspace);
    a("twin", twin);
    a.Require(!name.empty(), "name", "a task name");
    a.Require(!scene.empty(), "scene", "the path of the scene MJCF");
    a.Require(horizon > 0, "horizon", "a positive number of control steps");
    a.Require(!success.empty(), "success", "at least one success predicate");
  }
};

// Loads a task file, or DIR/task.yaml for a directory (a twin's); else a built-in task by name
// ("open_drawer": assets/tasks/<name>/task.yaml).
// Throws ConfigError naming the file, line and field.
TaskSpec LoadTaskSpec(const std::string& name_or_path);

// Names of the tasks shipped in assets/tasks.
std::vector<std::string> BuiltinTasks();

// Indices into the assembled model that the env, success checks and experts use.
struct TaskIndex {
  RobotIndex robot;
  std::vector<int> object_bodies;
  std::vector<int> state_joints;  // joint ids
  struct Predicate {
    PredicateType type;
    int a = -1, b = -1;  // sites, joint or body ids
    Eigen::Vector3d axis;
    double threshold;
  };
  std::vector<Predicate> predicates;
  std::vector<int> distractor_bodies;  // mocap bodies
  std::vector<int> distractor_geoms;
  int robot_mount = -1;                        // body holding the robot
  std::vector<std::vector<int>> group_bodies;  // per randomization group
  struct Disturbance {
    int body = -1, dof = -1;  // one of the two
  };
  std::vector<Disturbance> disturbances;  // per randomization.disturbances entry
  struct ExpertStepIds {
    int site = -1, joint = -1, carry = -1;  // -1 where the step names none
  };
  std::vector<ExpertStepIds> expert_steps;  // per expert step
};

// What a task's model is assembled from: its scene, and its robot (returned in `robot`) on its
// mount. Task adds the distractors and the timestep; the twin editor compiles just these.
// Throws ConfigError naming the task file if the scene does not exist.
MjcfParts SceneWithRobot(const TaskSpec& spec, RobotSpec& robot);

// A task ready to simulate: its spec, robot, assembled nominal model and resolved names.
// Immutable once built; environments copy the model and share the rest.
class Task {
 public:
  explicit Task(TaskSpec spec);
  // As above, then `edit` may change the compiled model's parameters (not its layout) before
  // anything copies it: how the proxy reality applies its hidden physics.
  using ModelEdit = std::function<void(mjModel*, const TaskIndex&)>;
  Task(TaskSpec spec, const ModelEdit& edit);

  const TaskSpec& spec() const { return spec_; }
  const RobotSpec& robot() const { return robot_; }
  const mjModel* model() const { return model_.get(); }
  const TaskIndex& index() const { return index_; }
  const std::string& mjcf() const { return mjcf_; }

  // Resolves a name of `type` in the model or throws ConfigError naming the task file and field.
  int Id(mjtObj type, const std::string& name, const std::string& field) const;

 private:
  TaskSpec spec_;
  RobotSpec robot_;
  std::string mjcf_;
  ModelPtr model_;
  TaskIndex index_;
};

}  // namespace twinforge::sim
