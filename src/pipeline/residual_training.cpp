#include "pipeline/residual_training.h"

#include <algorithm>
#include <charconv>
#include <cstring>
#include <fstream>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/fs.h"
#include "core/log.h"
#include "core/measure.h"
#include "learn/policy_net.h"
#include "learn/residual.h"
#include "pipeline/policy_operator.h"
#include "pipeline/residual_operator.h"
#include "pipeline/run_directory.h"
#include "sim/env.h"

namespace twinforge::pipeline {

namespace {

constexpr const char* kCurveHeader =
    "episode,seed,success,steps,transitions,critic_loss,actor_loss,q,seconds";

std::filesystem::path Beside(const std::filesystem::path& out, const std::string& suffix) {
  return out.string() + suffix;
}

std::filesystem::path Pending(const std::filesystem::path& path, int episodes) {
  return Beside(path, ".pending-" + std::to_string(episodes));
}

// Moves the files saved for `episodes` into place (if the run stopped before it could).
void FinishCommit(const std::filesystem::path& agent, const std::filesystem::path& buffer,
                  int episodes) {
  for (const auto& p : {agent, buffer})
    if (std::filesystem::exists(Pending(p, episodes)))
      std::filesystem::rename(Pending(p, episodes), p);
}

// Keeps the curve's header and its whole rows of episodes before `episodes` (a killed run may
// have left a row of an uncommitted episode, or half of one).
void TrimCurve(const std::filesystem::path& csv, int episodes) {
  std::ifstream in(csv);
  std::string text = std::string(kCurveHeader) + "\n", line;
  std::getline(in, line);  // the header, rewritten above
  const auto fields = std::count(kCurveHeader, kCurveHeader + std::strlen(kCurveHeader), ',') + 1;
  for (int n = 2; std::getline(in, line); ++n) {
    if (std::count(line.begin(), line.end(), ',') + 1 != fields) continue;  // cut short
    int episode = -1;
    const auto [end, ec] = std::from_chars(line.data(), line.data() + line.size(), episode);
    if (ec != std::errc() || *end != ',')
      throw core::Error(csv.string() + " line " + std::to_string(n) + ": not a curve row: " + line);
    if (episode < episodes) text += line + "\n";
  }
  core::WriteFileAtomic(csv, text);
}

// One episode's transitions: every decision is paired with the next; the last one gets the
// success reward and ends the episode when the robot reports success, and is dropped otherwise
// (the horizon cut it: there is no next observation to bootstrap from).
class EpisodeRecorder {
 public:
  EpisodeRecorder(learn::ReplayBuffer& buffer, int obs_dim)
      : buffer_(buffer),
        obs_(obs_dim),
        base_(sim::kContinuousActionDim),
        action_(sim::kContinuousActionDim) {}
  void Begin() {
    pending_ = false;
    steps_ = 0;
  }
  void Decide(const ResidualOperator::Decision& d) {
    if (pending_) {
      buffer_.Add(obs_.data(), base_.data(), action_.data(), 0.0f, d.obs, d.base, false);
      ++recorded_;
    }
    std::copy_n(d.obs, obs_.size(), obs_.data());
    std::copy_n(d.base, base_.size(), base_.data());
    std::copy_n(d.action, action_.size(), action_.data());
    pending_ = true;
    ++steps_;
  }
  void End(bool success) {
    if (pending_ && success) {
      buffer_.Add(obs_.data(), base_.data(), action_.data(), 1.0f, obs_.data(), base_.data(), true);
      ++recorded_;
    }
    pending_ = false;
  }
  int steps() const { return steps_; }
  int64_t recorded() const { return recorded_; }

 private:
  learn::ReplayBuffer& buffer_;
  std::vector<float> obs_, base_, action_;
  bool pending_ = false;
  int steps_ = 0;
  int64_t recorded_ = 0;
};

}  // namespace

ResidualTrainReport TrainResidualOnReality(reality::Robot& robot,
                                           const std::filesystem::path& base_policy,
                                           const sim::TaskSpec& task,
                                           const ResidualTrainOptions& options,
                                           const std::filesystem::path& out, bool fresh,
                                           core::Progress* progress) {
  learn::PolicyNet net = LoadRobotPolicy(base_policy, task);
  PolicyOperator op(robot, net, task, options.scene_points, options.arm_points, options.sample,
                    true);
  return TrainResidualOnReality(robot,
                                PolicyResidualBase(op, Fingerprint().AddFile(base_policy).Hex()),
                                task, options, out, fresh, progress);
}

ResidualTrainReport TrainResidualOnReality(reality::Robot& robot, const ResidualBase& base,
                                           const sim::TaskSpec& task,
                                           const ResidualTrainOptions& options,
                                           const std::filesystem::path& out, bool fresh,
                                           core::Progress* progress) {
  const auto start = core::Clock::now();
  const reality::RobotInfo info = robot.Info();
  if (!info.has_success_oracle)
    throw core::Error(info.name +
                      " cannot tell success by itself, and the residual learns from that reward");

  ResidualTrainReport report;
  report.residual = out;
  report.curve_csv = Beside(out, ".curve.csv");
  const auto buffer_path = Beside(out, ".buffer"), state_path = Beside(out, ".state.json");
  const int obs_dim = base.feature_dim;
  learn::OffPolicyAgent agent(obs_dim, sim::kContinuousActionDim, options.agent);
  learn::ReplayBuffer buffer(obs_dim, sim::kContinuousActionDim,
                             int64_t(options.episodes) * task.horizon + 1);
  core::Rng update_rng(options.seed, 0x7e5d);
  // What a resumed run must share with the one it continues: all but the episode budget.
  nlohmann::json same_options = core::ToJson(options);
  same_options.erase("episodes");
  const nlohmann::json fingerprint = {{"base", base.identity},
                                      {"task", task.name},
                                      {"robot", info.name},
                                      {"options", same_options}};

  // Resume after the last whole episode, or start over.
  int first = 0;
  if (fresh)
    for (const auto& p : {out, buffer_path, state_path, report.curve_csv})
      std::filesystem::remove(p);
  if (std::filesystem::exists(state_path)) {
    const nlohmann::json state =
        nlohmann::json::parse(core::ReadTextFile(state_path), nullptr, false);
    if (state.is_discarded() || state.value("fingerprint", nlohmann::json()) != fingerprint)
      throw core::Error(state_path.string() +
                        ": a residual run of another base, task, robot or options; pass "
                        "--fresh to start over or give another --out");
    first = state.at("episodes").get<int>();
    if (first > options.episodes)
      throw core::Error(state_path.string() + ": " + std::to_string(first) +
                        " episodes are done already, more than the " +
                        std::to_string(options.episodes) + " asked for");
    FinishCommit(out, buffer_path, first);
    agent.Load(out);
    buffer.Load(buffer_path);
    TrimCurve(report.curve_csv, first);
    update_rng.Load(state.at("update_rng").get<std::string>());
    report.successes = state.at("successes").get<int>();
    report.transitions = buffer.size();
    report.resumed_from = first;
    spdlog::info("residual: resuming {} after episode {}", out.string(), first);
  } else {
    if (out.has_parent_path()) std::filesystem::create_directories(out.parent_path());
    std::ofstream(report.curve_csv) << kCurveHeader << "\n";
  }
  std::ofstream curve(report.curve_csv, std::ios::app);
  if (!curve) throw core::IoError("cannot write " + report.curve_csv.string());

  agent.info()["base"] = base.identity;
  reality::ActionClient client(robot, task.control.limits);
  ResidualOperator op(base, agent, client, task.control.limits, true);
  EpisodeRecorder recorder(buffer, obs_dim);
  op.on_decision = [&](const ResidualOperator::Decision& d) { recorder.Decide(d); };
  if (progress) progress->Set(first);

  for (int e = first; e < options.episodes; ++e) {
    const uint64_t seed = core::MixSeed(options.seed, uint64_t(e));
    reality::Observation o = robot.Reset({seed, options.level});
    client.ResetGripper();
    op.Begin(seed);
    recorder.Begin();
    reality::RunOperator(robot, op, client, o, task.horizon, true);
    const bool success = robot.QuerySuccess() == reality::SuccessAnswer::kSuccess;
    recorder.End(success);
    report.successes += success;

    // Learn between episodes, while the robot waits: critics alone at first.
    const bool train_actor = e >= options.critic_episodes;
    learn::OffPolicyStats last;
    double critic = 0, actor = 0, q = 0;
    int n = 0, actor_n = 0;
    if (buffer.size() > 0) {
      for (int u = 0; u < recorder.steps() * options.updates_per_step; ++u) {
        last = agent.Update(buffer, update_rng, train_actor);
        critic += last.critic_loss;
        q += last.q;
        ++n;
        if (last.actor_updated) {
          actor += last.actor_loss;
          ++actor_n;
        }
      }
    }
    report.updates += n;
    // The curve row, the agent and the buffer under names of this episode, then the state
    // (the commit), then the renames; a resume finishes renames the state already counts.
    curve << e << "," << seed << "," << success << "," << recorder.steps() << "," << buffer.size()
          << "," << (n ? critic / n : 0) << "," << (actor_n ? actor / actor_n : 0) << ","
          << (n ? q / n : 0) << "," << core::SecondsSince(start) << "\n"
          << std::flush;
    agent.Save(Pending(out, e + 1));
    buffer.Save(Pending(buffer_path, e + 1));
    core::WriteFileAtomic(state_path, nlohmann::json{{"fingerprint", fingerprint},
                                                     {"episodes", e + 1},
                                                     {"successes", report.successes},
                                                     {"update_rng", update_rng.Save()}}
                                          .dump(2));
    FinishCommit(out, buffer_path, e + 1);
    if (progress)
      progress->Advance(1, std::string(success ? "success" : "failure") + ", " +
                               std::to_string(report.successes) + "/" + std::to_string(e + 1) +
                               (train_actor ? "" : " (critic only)"));
  }
  report.episodes = options.episodes;
  report.transitions = buffer.size();
  report.seconds = core::SecondsSince(start);
  return report;
}

}  // namespace twinforge::pipeline
