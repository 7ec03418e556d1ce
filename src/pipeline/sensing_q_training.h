// SAM-RL's sensing-aware Q learned from simulated episodes (`train samrl`). The twin actor runs
// episodes in the twin itself (ProxyReality::SimulatedTwin: the twin's physics, an ideal sensor),
// looking as eval's does (first, then again after the expert steps marked `look`), each look
// from a camera pose drawn on the orbit mount. The view it would render in the twin from that
// pose, as it believed the scene then (with what its earlier frames showed in the way, as the
// active look renders it), and its plan then (the expert step it does next) are
// paired with the episode's return (1 on success, else 0), and Q(view, plan) is fitted to the
// returns by regression. At run time (`eval --actor twin --look q`) each look takes the view Q
// scores best for the actor's plan, in the twin as the actor believes it.
//
// The episodes are seeded trials of the evaluation harness (EvaluateOperatorOnReality), split
// among worker threads, each with its own simulated twin and log: a killed run resumes after the
// episodes its logs hold, and which episodes run does not depend on the number of workers.
//
// Includes <torch/torch.h> (via samrl/sensing_q.h): include it from .cpp files only.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>

#include "core/pinhole.h"
#include "core/progress.h"
#include "samrl/active_camera.h"
#include "samrl/sensing_q.h"
#include "samrl/twin_actor.h"
#include "sim/task.h"

namespace twinforge::pipeline {

struct SensingQTrainOptions {
  int episodes = 120;  // simulated episodes
  int level = 1;       // the twin's randomization level
  // Looks per episode at most, each from a random view (the actor looks again as eval's does);
  // every look is a sample for Q. Eval's own budget since stop 92: the Q is fitted to the episodes
  // of the actor it serves. With 3 (before), the hidden peg's twin at level 3 succeeded in 39 of
  // 100 episodes, with 5 in 53 (seeds 9100): 67 had used every look.
  int max_looks = samrl::RelookOptions{}.max_looks;
  // Q reads the actor's plan at the look (the expert step it does next) as its action; false: the
  // view alone (as before stop 44).
  bool plan = true;
  // Q's return:
  // - kSuccess: the episode's success (1 or 0);
  // - kCloseness: how near the simulated twin was to success at the end
  //   (sim::Env::SuccessCloseness: 1 on success, a peg beside its hole more than one on the floor);
  // - kLook: the look's own return, the share of the objects it was to show (those not held)
  //   that the actor believed, once it had looked, within `look_tolerance` of where they stood
  //   in the twin (in the table's plane). An episode's return is shared by its looks, and its
  //   other looks came from random views too: on the hidden peg at level 3 no class of looks
  //   (azimuth, targets shown, which look) predicted other episodes' success better than their
  //   mean by more than 1% (stop 92), though the actor's own views succeed where random ones
  //   fail. A look's own return says what that view did.
  enum class Return { kSuccess, kCloseness, kLook };
  Return ret = Return::kSuccess;
  double look_tolerance = 0.003;  // m
  uint64_t seed = 7000;
  int workers = 2;  // threads, each running its own simulated twin
  // The simulated frames: this times the task camera's resolution, as eval --actor twin's.
  int capture_scale = 8;
  // Adam steps: 300. On the occluded peg's 100 episodes of up to 3 looks (stop 44), no count
  // from 50 to 300 predicted held-out episodes' success better than their mean did.
  samrl::SensingQOptions fit = DefaultFit();
  static samrl::SensingQOptions DefaultFit() {
    samrl::SensingQOptions o;
    o.steps = 300;
    return o;
  }
};

struct SensingQTrainReport {
  int episodes = 0, successes = 0, resumed = 0;
  int looks = 0;  // samples Q was fitted to
  samrl::SensingQReport fit;
  samrl::ViewChoice chosen;  // the view Q scores best with the twin at home and the arm at rest
  std::filesystem::path q_file;
  double seconds = 0;
};

// --return's name of a return: success, closeness or look.
const char* ReturnName(SensingQTrainOptions::Return ret);

// The twin task's identity by content (its task file and scene).
std::string TwinFingerprint(const sim::TaskSpec& twin);

// Runs the episodes under `out_dir` (episodes.<worker>.jsonl, and their looks in
// looks.<worker>.jsonl), fits Q and writes out_dir/q.pt
// with out_dir/q.json beside it (what it was trained on and how well it fits).
SensingQTrainReport TrainSensingQ(const sim::TaskSpec& twin, const SensingQTrainOptions& options,
                                  const std::filesystem::path& out_dir,
                                  core::Progress* progress = nullptr);

// A Q as `train samrl` wrote it, with the mount and render it reads views from.
struct SensingQModel {
  samrl::SensingQNet net{nullptr};
  samrl::OrbitMount mount;
  core::PinholeIntrinsics search;
  std::string hash;  // of q.pt, for a trial log's header
};
// Loads `q_file` (q.pt; q.json beside it). Throws naming the file when either is missing or
// malformed, or when it was trained on another twin than `twin`.
SensingQModel LoadSensingQ(const std::filesystem::path& q_file, const sim::TaskSpec& twin);

}  // namespace twinforge::pipeline
