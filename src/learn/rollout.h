// Episodes of a policy network in the sim: what `sim eval` measures, what inverse distillation
// records and what PPO's periodic evaluation runs. A point-cloud policy sees the task camera's
// ray-cast clouds (depth-noise model; arm points from forward kinematics); a state policy (no
// point features) sees the privileged state.
//
// Includes <torch/torch.h> (via policy_net.h): include it only from learn's .cpp files and tests.
#pragma once

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "core/dataset.h"
#include "core/rng.h"
#include "learn/distill.h"
#include "learn/evaluate.h"
#include "learn/policy_net.h"
#include "sim/action.h"
#include "sim/task.h"

namespace twinforge::learn {

struct PolicyEpisode {
  int steps = -1;        // control steps to success, -1 on failure
  core::Episode record;  // when asked for: every step up to success (or the horizon)
};

// A move drawn from `probabilities` (n of them, summing to 1): one uniform draw, the cumulative
// distribution inverted. PPO's rollouts and sampled evaluation both draw this way.
int SampleIndex(const float* probabilities, int n, core::Rng& rng);
// The continuous action mean + scale * exp(log_std) * N(0, 1), per component (scale 0: the mean).
sim::Action SampleGaussian(const float* mean, const float* log_std, double scale, core::Rng& rng);

// The action a policy output [1, action_dim] asks for: the most likely move (the mean) or, with
// options.sample, one drawn at options.temperature.
sim::Action ChooseAction(const PolicyNet& net, const torch::Tensor& out,
                         const PolicyEvalOptions& options, core::Rng& rng);

// A continuous policy's action_scale for a task: its per-step limits (translation x 3, rotation
// x 3) and 1 for the gripper command.
std::vector<double> ContinuousActionScale(const sim::ActionLimits& limits);

// Throws Error naming `what` (e.g. the policy file) when the network's inputs or actions do not
// fit the task.
void CheckPolicyFitsTask(const PolicyConfig& config, const sim::Task& task,
                         const std::string& what);
// A policy file's network in evaluation mode; throws Error naming the file when it does not fit
// the task.
PolicyNet LoadPolicyFor(const std::filesystem::path& policy, const sim::Task& task);

// Runs episodes first .. first + count - 1, episode i reset with MixSeed(options.seed, i) at
// options.level, split over options.threads; the outcome does not depend on the thread count.
// With `record`, each episode keeps its steps (actions, privileged `states`, rewards, dones,
// obs/proprio and, for a point-cloud policy, obs/scene_points and obs/arm_points).
std::vector<PolicyEpisode> RunPolicyEpisodes(PolicyNet& net, std::shared_ptr<const sim::Task> task,
                                             const PolicyEvalOptions& options, int64_t first,
                                             int64_t count, bool record);

// Success rate of an in-memory policy over options.episodes.
PolicyEvalReport EvaluatePolicy(PolicyNet& net, std::shared_ptr<const sim::Task> task,
                                const PolicyEvalOptions& options);

// Episodes for teacher-student distillation: `actor` acts (the teacher; the student in DAgger)
// and the teacher labels every step with its move probabilities (or its mean). Each step keeps
// the clouds (ray-cast with depth noise when `rendered`, else sampled on the surfaces), the
// proprioception, the privileged state, the action taken and the label. Episode i is reset with
// MixSeed(seed, i) at `level`; failed episodes are dropped unless `keep_failures`, successful
// ones end at their first success. The outcome does not depend on the thread count.
struct DistillRollout {
  int level = 1;
  bool rendered = true;
  bool keep_failures = false;
  bool sample = true;  // the actor samples its moves (else the most likely / the mean)
  int scene_points = 1024, arm_points = 256;
  int student_points = 512;  // points the student acting in DAgger sees
  uint64_t seed = 0;
  int threads = 1;
};
struct DistillCollection {
  DistillSource data;
  int episodes = 0, successes = 0, kept = 0;
};
DistillCollection CollectDistill(PolicyNet& teacher, PolicyNet* actor,
                                 std::shared_ptr<const sim::Task> task,
                                 const DistillRollout& options, int64_t first, int64_t count);

// TrainDistill's stages in order (a stage of 0 episodes is skipped), and the rollout of stage k.
struct DistillStage {
  std::string name;
  int episodes = 0, level = 1;
  bool rendered = true, dagger = false;
};
std::vector<DistillStage> DistillStages(const DistillOptions& options);
DistillRollout DistillStageRollout(const DistillOptions& options, std::size_t k);

}  // namespace twinforge::learn
