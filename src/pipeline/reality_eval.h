// A point-cloud policy on reality (a real robot or the proxy reality), RialTo's way: seeded
// trials at each randomization level, actions through the bridge and the safety filter, success
// from the robot's oracle (the proxy's) or else asked of the person at the robot, and a
// bootstrapped 95% interval per level.
//
// Every trial is appended to a JSON-lines log as it ends. Its first line names the policy (by
// content) and the protocol; running again with the same log resumes after the trials already in
// it, and a log of another policy or protocol is refused by name.
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <nlohmann/json.hpp>
#include <string>
#include <utility>
#include <vector>

#include "core/progress.h"
#include "core/rng.h"
#include "reality/robot.h"
#include "reality/teleop.h"
#include "sim/task.h"

namespace twinforge::pipeline {

struct TrialRecord {
  int level = 0, trial = 0;
  uint64_t seed = 0;
  bool success = false;
  int steps = 0;  // actions sent
  double seconds = 0;
  nlohmann::json grader;  // RealityEvalOptions::grader's answer, if asked
};

struct RealityEvalOptions {
  std::vector<int> levels = {1, 2, 3};
  int trials = 50;          // per level
  uint64_t seed = 5000;     // trial i at level L: reset seed MixSeed(seed, 1000 * L + i)
  bool sample = false;      // sample the policy's moves (else the most likely)
  int scene_points = 2048;  // as `demos record` stores them
  int arm_points = 512;
  int bootstrap = 2000;  // resamples for the interval
  // If set: the camera's last frame of each level's first success and first failure, as
  // PNG files named level<L>_trial<i>_<success|failure>.png.
  std::filesystem::path frames;
  // If set: a residual (`train residual`) adds its correction to the policy's actions.
  std::filesystem::path residual;
  // If set: a grader's view of the scene at each trial's end (a proxy world's hidden state),
  // logged with the trial as "grader". Diagnosis only; the policy never sees it.
  std::function<nlohmann::json()> grader;
  // If set: every step of every trial run (not resumed ones) appended here as JSON lines: level,
  // trial, step, the action, the tool position and gripper width the robot reported before it,
  // and the grader's view when `grader` is set. To see where failing trials go.
  std::filesystem::path trace;
  // A log of another policy, residual, task or protocol is renamed LOG.previous and a new one
  // started (else it is an error).
  bool set_aside_other_logs = false;
  // Only the trials i with i % workers == worker run here (their seeds unchanged): trials split
  // among threads or processes, each with its own robot and log.
  int worker = 0, workers = 1;
  // If set: called after each trial this call counts (run or read back), e.g. for a progress line
  // shared by workers.
  std::function<void(const TrialRecord&)> on_trial;
};

struct LevelResult {
  int level = 0, trials = 0, successes = 0;
  double rate = 0, low = 0, high = 0;  // bootstrapped 95% interval
};

struct RealityEvalReport {
  std::vector<LevelResult> levels;
  std::vector<TrialRecord> trials;
  int resumed = 0;  // trials read back from the log rather than run
  double seconds = 0;
};

// The per-level rates with their intervals, as the commands print and the report reads them.
nlohmann::json ToJson(const RealityEvalReport& report);

// Percentile bootstrap of a success rate: the 2.5% and 97.5% quantiles of the rate over
// `resamples` resamplings (with replacement) of the trials' outcomes.
std::pair<double, double> BootstrapInterval(int successes, int trials, int resamples,
                                            core::Rng& rng);

// When the robot has no success oracle, `judge` is asked after each trial (a person at the
// robot); without one such a robot is refused.
using SuccessJudge = std::function<bool(const TrialRecord&)>;

RealityEvalReport EvaluateOnReality(reality::Robot& robot, const std::filesystem::path& policy,
                                    const sim::TaskSpec& task, const RealityEvalOptions& options,
                                    const std::filesystem::path& log,
                                    const SuccessJudge& judge = nullptr,
                                    core::Progress* progress = nullptr);

// The same trials for any base a residual can sit on (a point-cloud policy, the twin actor), with
// options.residual on its actions when set; `header` names the base in the log.
struct ResidualBase;
RealityEvalReport EvaluateBaseOnReality(reality::Robot& robot, const ResidualBase& base,
                                        nlohmann::json header, const sim::TaskSpec& task,
                                        const RealityEvalOptions& options,
                                        const std::filesystem::path& log,
                                        const SuccessJudge& judge = nullptr,
                                        core::Progress* progress = nullptr);

// What the trials run when it is not a point-cloud policy (SAM-RL's twin actor): an operator at
// the robot's controls, begun before each trial with the trial's seed, and the log header that
// names it. A log is resumed when its header names the same thing: every key compared, except
// the file paths "policy" and "residual" (the same file may move).
struct TrialOperator {
  reality::Operator* op = nullptr;
  std::function<void(uint64_t seed)> begin;
  nlohmann::json header;
  reality::ActionClient* client = nullptr;  // sends the actions (null: one of the task's limits)
};
// The same trials, log and intervals for any operator; options' policy-only fields (sample,
// points, residual) are the caller's to honour.
RealityEvalReport EvaluateOperatorOnReality(reality::Robot& robot, const TrialOperator& subject,
                                            const sim::TaskSpec& task,
                                            const RealityEvalOptions& options,
                                            const std::filesystem::path& log,
                                            const SuccessJudge& judge = nullptr,
                                            core::Progress* progress = nullptr);

}  // namespace twinforge::pipeline
