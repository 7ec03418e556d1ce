#include "pipeline/reality_eval.h"

#include <algorithm>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>

#include "core/error.h"
#include "core/image.h"
#include "core/log.h"
#include "core/measure.h"
#include "learn/policy_net.h"
#include "learn/rollout.h"
#include "pipeline/policy_operator.h"
#include "pipeline/run_directory.h"
#include "reality/teleop.h"
#include "sim/env.h"

namespace twinforge::pipeline {

nlohmann::json ToJson(const RealityEvalReport& r) {
  nlohmann::json levels = nlohmann::json::array();
  for (const auto& l : r.levels)
    levels.push_back({{"level", l.level},
                      {"trials", l.trials},
                      {"successes", l.successes},
                      {"success_rate", l.rate},
                      {"interval_95", {l.low, l.high}}});
  return {{"levels", levels}, {"resumed_trials", r.resumed}, {"seconds", r.seconds}};
}

std::pair<double, double> BootstrapInterval(int successes, int trials, int resamples,
                                            core::Rng& rng) {
  if (trials <= 0) return {0.0, 0.0};
  const double p = double(successes) / trials;
  std::vector<double> rates(std::max(resamples, 1));
  for (double& r : rates) {
    int s = 0;
    for (int i = 0; i < trials; ++i) s += rng.Uniform() < p;
    r = double(s) / trials;
  }
  std::sort(rates.begin(), rates.end());
  const auto at = [&](double q) {
    return rates[std::min(rates.size() - 1, static_cast<std::size_t>(q * double(rates.size())))];
  };
  return {at(0.025), at(0.975)};
}

namespace {

nlohmann::json ToJson(const TrialRecord& t) {
  nlohmann::json j = {{"level", t.level},     {"trial", t.trial}, {"seed", t.seed},
                      {"success", t.success}, {"steps", t.steps}, {"seconds", t.seconds}};
  if (!t.grader.is_null()) j["grader"] = t.grader;
  return j;
}

}  // namespace

RealityEvalReport EvaluateOnReality(reality::Robot& robot, const std::filesystem::path& policy,
                                    const sim::TaskSpec& task, const RealityEvalOptions& options,
                                    const std::filesystem::path& log, const SuccessJudge& judge,
                                    core::Progress* progress) {
  if (options.trials <= 0 || options.levels.empty())
    throw core::ConfigError("eval", "trials", "at least one trial at one level");
  learn::PolicyNet net = LoadRobotPolicy(policy, task);
  const std::string hash = Fingerprint().AddFile(policy).Hex();
  const nlohmann::json header = {{"policy", policy.string()},
                                 {"policy_hash", hash},
                                 {"sample", options.sample},
                                 {"points", {options.scene_points, options.arm_points}}};
  PolicyOperator op(robot, net, task, options.scene_points, options.arm_points, options.sample,
                    robot.Info().has_success_oracle);
  return EvaluateBaseOnReality(robot, PolicyResidualBase(op, hash), header, task, options, log,
                               judge, progress);
}

RealityEvalReport EvaluateBaseOnReality(reality::Robot& robot, const ResidualBase& base,
                                        nlohmann::json header, const sim::TaskSpec& task,
                                        const RealityEvalOptions& options,
                                        const std::filesystem::path& log, const SuccessJudge& judge,
                                        core::Progress* progress) {
  reality::ActionClient client(robot, task.control.limits);
  if (options.residual.empty())
    return EvaluateOperatorOnReality(robot, {base.op, base.begin, header, &client}, task, options,
                                     log, judge, progress);
  const auto residual = learn::OffPolicyAgent::Open(options.residual);
  CheckResidualFits(*residual, base, options.residual.string());
  header["residual"] = options.residual.string();
  header["residual_hash"] = Fingerprint().AddFile(options.residual).Hex();
  ResidualOperator op(base, *residual, client, task.control.limits, false);
  return EvaluateOperatorOnReality(robot,
                                   {&op, [&](uint64_t seed) { op.Begin(seed); }, header, &client},
                                   task, options, log, judge, progress);
}

RealityEvalReport EvaluateOperatorOnReality(reality::Robot& robot, const TrialOperator& subject,
                                            const sim::TaskSpec& task,
                                            const RealityEvalOptions& options,
                                            const std::filesystem::path& log,
                                            const SuccessJudge& judge, core::Progress* progress) {
  const auto start = core::Clock::now();
  if (options.trials <= 0 || options.levels.empty())
    throw core::ConfigError("eval", "trials", "at least one trial at one level");
  if (options.workers < 1 || options.worker < 0 || options.worker >= options.workers)
    throw core::ConfigError("eval", "worker",
                            "worker " + std::to_string(options.worker) + " of " +
                                std::to_string(options.workers) + " (0 <= worker < workers)");
  const reality::RobotInfo info = robot.Info();
  if (!info.has_success_oracle && !judge)
    throw core::Error(info.name + " cannot tell success by itself and no one was asked to judge");

  // The log: a header naming what runs and the protocol, then one line per trial.
  nlohmann::json header = subject.header;
  header["task"] = task.name;
  header["robot"] = info.name;
  header["seed"] = options.seed;
  std::map<std::pair<int, int>, TrialRecord> done;
  auto same_trials = [&] {
    std::ifstream in(log);
    std::string line;
    std::getline(in, line);
    const nlohmann::json old = nlohmann::json::parse(line, nullptr, false);
    if (old.is_discarded() || !old.is_object()) return false;
    const auto identifies = [](const std::string& key) {
      return key != "policy" && key != "residual";
    };
    for (const auto& [key, value] : header.items())
      if (identifies(key) && (!old.contains(key) || old[key] != value)) return false;
    for (const auto& [key, value] : old.items())
      if (identifies(key) && !header.contains(key)) return false;
    return true;
  };
  if (std::filesystem::exists(log) && std::filesystem::file_size(log) > 0 && !same_trials()) {
    if (!options.set_aside_other_logs)
      throw core::Error(
          log.string() +
          ": a trial log of another policy, residual, actor, task or protocol; give another --out "
          "or remove it");
    std::filesystem::path previous = log;
    previous += ".previous";
    spdlog::info("eval: {} holds other trials; kept as {}", log.string(), previous.string());
    std::filesystem::rename(log, previous);
  }
  if (std::filesystem::exists(log) && std::filesystem::file_size(log) > 0) {
    std::ifstream in(log);
    std::string line;
    std::getline(in, line);
    for (int n = 2; std::getline(in, line); ++n) {
      const nlohmann::json t = nlohmann::json::parse(line, nullptr, false);
      if (t.is_discarded()) {
        spdlog::warn("eval: {} line {} is cut short (a killed run); that trial runs again",
                     log.string(), n);
        break;
      }
      TrialRecord r{t.at("level"),
                    t.at("trial"),
                    t.at("seed"),
                    t.at("success"),
                    t.at("steps"),
                    t.at("seconds"),
                    t.value("grader", nlohmann::json())};
      done[{r.level, r.trial}] = r;
    }
  } else {
    if (log.has_parent_path()) std::filesystem::create_directories(log.parent_path());
    std::ofstream(log) << header.dump() << "\n";
  }
  std::ofstream out(log, std::ios::app);
  if (!out) throw core::IoError("cannot write " + log.string());
  std::ofstream trace;
  if (!options.trace.empty()) {
    trace.open(options.trace, std::ios::app);
    if (!trace)
      throw core::IoError("eval: cannot write the step trace to " + options.trace.string());
  }

  std::optional<reality::ActionClient> own;
  if (!subject.client) own.emplace(robot, task.control.limits);
  reality::ActionClient& client = subject.client ? *subject.client : *own;
  RealityEvalReport report;
  for (int level : options.levels) {
    bool shown[2] = {false, false};  // a failure's frame, a success's frame
    LevelResult result;
    result.level = level;
    for (int i = options.worker; i < options.trials; i += options.workers) {
      const auto it = done.find({level, i});
      TrialRecord r;
      if (it != done.end()) {
        r = it->second;
        ++report.resumed;
      } else {
        const auto trial_start = core::Clock::now();
        r.level = level;
        r.trial = i;
        r.seed = core::MixSeed(options.seed, 1000 * uint64_t(level) + uint64_t(i));
        reality::Observation o = robot.Reset({r.seed, level});
        client.ResetGripper();
        subject.begin(r.seed);
        int step = 0;
        const reality::BeforeAct trace_step = [&](const reality::Observation& seen,
                                                  const sim::Action& action) {
          const core::Vec3& t = seen.ee.translation;
          const core::Quat& r = seen.ee.rotation;
          nlohmann::json j = {
              {"level", level},
              {"trial", i},
              {"step", step++},
              {"action", sim::ToJson(action)},
              {"tool", {t.x(), t.y(), t.z()}},
              {"tool_quat", {r.w(), r.x(), r.y(), r.z()}},
              {"q", std::vector<double>(seen.q.data(), seen.q.data() + seen.q.size())},
              {"gripper_width", seen.gripper_width}};
          if (options.grader) j["grader"] = options.grader();
          trace << j.dump() << "\n";
        };
        r.steps = reality::RunOperator(robot, *subject.op, client, o, task.horizon, true,
                                       trace.is_open() ? trace_step : reality::BeforeAct())
                      .actions;
        if (trace.is_open()) trace << std::flush;
        const reality::SuccessAnswer answer = robot.QuerySuccess();
        r.success = answer == reality::SuccessAnswer::kUnknown
                        ? (judge ? judge(r) : false)
                        : answer == reality::SuccessAnswer::kSuccess;
        r.seconds = core::SecondsSince(trial_start);
        if (options.grader) r.grader = options.grader();
        if (!options.frames.empty() && !shown[r.success] && !o.frames.empty() &&
            !o.frames.front().rgb.empty()) {
          shown[r.success] = true;
          const reality::RgbdFrame& f = o.frames.front();
          std::filesystem::create_directories(options.frames);
          core::WritePng(
              options.frames / ("level" + std::to_string(level) + "_trial" + std::to_string(i) +
                                (r.success ? "_success.png" : "_failure.png")),
              {f.intrinsics.width, f.intrinsics.height, 3, 8, f.rgb});
        }
        out << ToJson(r).dump() << "\n" << std::flush;
      }
      ++result.trials;
      result.successes += r.success;
      report.trials.push_back(r);
      if (options.on_trial) options.on_trial(r);
      if (progress)
        progress->Advance(1, "level " + std::to_string(level) + ": " +
                                 std::to_string(result.successes) + "/" +
                                 std::to_string(result.trials));
    }
    result.rate = double(result.successes) / result.trials;
    core::Rng rng(options.seed, 0xb007 + level);
    std::tie(result.low, result.high) =
        BootstrapInterval(result.successes, result.trials, options.bootstrap, rng);
    spdlog::info("eval: level {}: {}/{} ({:.0f}%, 95% interval {:.0f}-{:.0f}%)", level,
                 result.successes, result.trials, 100 * result.rate, 100 * result.low,
                 100 * result.high);
    report.levels.push_back(result);
  }
  report.seconds = core::SecondsSince(start);
  return report;
}

}  // namespace twinforge::pipeline
