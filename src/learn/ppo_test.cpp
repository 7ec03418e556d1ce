#include "learn/ppo.h"

#include <gtest/gtest.h>

#include <fstream>
#include <sstream>

#include "core/error.h"
#include "core/test_support.h"
#include "learn/evaluate.h"
#include "learn/policy_net.h"
#include "learn/ppo_update.h"
#include "learn/rollout.h"
#include "learn/test_support.h"
#include "learn/torch_runtime.h"
#include "sim/env.h"

namespace twinforge::learn {
namespace {

std::vector<std::vector<std::string>> ReadCsv(const std::filesystem::path& path) {
  std::ifstream in(path);
  std::vector<std::vector<std::string>> rows;
  for (std::string line; std::getline(in, line);) {
    rows.emplace_back();
    std::stringstream s(line);
    for (std::string cell; std::getline(s, cell, ',');) rows.back().push_back(cell);
  }
  return rows;
}

double MeanColumn(const std::vector<std::vector<std::string>>& rows, std::size_t first,
                  std::size_t last, int column) {
  double sum = 0;
  for (std::size_t i = first; i < last; ++i) sum += std::stod(rows[i][column]);
  return sum / double(last - first);
}

PpoOptions SmallOptions() {
  PpoOptions o;
  o.num_envs = 16;
  o.threads = 2;
  o.eval_every = 5;
  o.eval_episodes = 30;
  o.max_seconds = 0;
  return o;
}

// How TrainPpo evaluates with these options: a policy file it wrote evaluates the same again.
PolicyEvalOptions EvalOptionsOf(const PpoOptions& o) {
  PolicyEvalOptions e;
  e.episodes = o.eval_episodes;
  e.level = o.level;
  e.seed = o.eval_seed;
  e.sample = o.eval_sample;
  return e;
}

// One quick iteration, for the checkpoint tests.
PpoOptions OneIteration() {
  PpoOptions o = SmallOptions();
  o.num_envs = 4;
  o.epochs = 1;
  o.max_iterations = 1;
  return o;
}

// From a few percent of sampled episodes to most of them, and the policy file written is the one
// whose evaluation was best.
TEST(Ppo, ImprovesSuccessOnATinyTask) {
  PinMathThreads(1);
  auto task = testing::ReachTask();
  const auto dir = core::testing::TestDir("ppo_test", "improves");
  PpoOptions o = SmallOptions();
  o.max_iterations = 25;
  o.target_success = 1.01;  // run the whole budget
  const PpoReport r = TrainPpo(task, "", dir / "teacher.pt", o, CheckpointMode::kStartOver);
  EXPECT_EQ(r.iterations, 25);
  EXPECT_EQ(r.stopped_by, "iterations");
  const auto rows = ReadCsv(r.curve_csv);
  ASSERT_EQ(rows.size(), 26u);
  EXPECT_EQ(rows[0][3], "rollout_success");
  const double early = MeanColumn(rows, 1, 4, 3), late = MeanColumn(rows, 23, 26, 3);
  EXPECT_LT(early, 0.25);
  EXPECT_GT(late, 0.5) << "early " << early;
  EXPECT_GE(r.best_eval_success, 0.7);
  EXPECT_GT(r.update_samples_per_s, 0);
  EXPECT_GT(r.matmul_peak_gflops, 1);  // measured in the same process
  EXPECT_GT(r.update_share_of_matmul_peak, 0.001);
  EXPECT_LT(r.update_share_of_matmul_peak, 1.5);
  EXPECT_TRUE(std::filesystem::exists(r.curve_svg));

  EXPECT_DOUBLE_EQ(EvaluatePolicy(dir / "teacher.pt", task, EvalOptionsOf(o)).success_rate(),
                   r.best_eval_success);
}

void ExpectSameWeights(const std::filesystem::path& a, const std::filesystem::path& b) {
  PolicyNet x = LoadPolicy(a), y = LoadPolicy(b);
  const auto px = x->named_parameters(), py = y->named_parameters();
  ASSERT_EQ(px.size(), py.size());
  for (const auto& p : px) EXPECT_TRUE(torch::equal(p.value(), py[p.key()])) << p.key();
  EXPECT_TRUE(torch::equal(x->obs_mean, y->obs_mean));
  EXPECT_TRUE(torch::equal(x->obs_std, y->obs_std));
}

// Sim demos for the BC loss, from an untrained sampled state policy on the tiny task.
std::filesystem::path TinyDemos(const std::filesystem::path& dir, int successes = 2) {
  auto task = testing::ReachTask();
  torch::manual_seed(3);
  PolicyNet net(testing::StatePolicyConfig(*task));
  SavePolicy(net, dir / "random.pt");
  InverseDistillOptions o;
  o.rollout.sample = true;
  o.rollout.episodes = 400;
  o.rollout.threads = 2;
  o.successes = successes;
  std::filesystem::remove(dir / "sim.hdf5");
  const InverseDistillReport r = InverseDistill(dir / "random.pt", task, o, dir / "sim.hdf5");
  EXPECT_EQ(r.successes, successes);
  return dir / "sim.hdf5";
}

// Killed after iteration 2 and resumed (on another thread count), a run with a BC loss matches an
// uninterrupted one step for step: the same curve and the same weights. The reach is loose
// enough that episodes succeed before the kill, so rewards (and the returns' normalizer, which
// a resume must restore whole) are not all zero.
TEST(Ppo, AResumedRunMatchesAnUninterruptedOne) {
  PinMathThreads(1);
  auto task = testing::ReachTask(0.25);
  const auto dir = core::testing::TestDir("ppo_test", "resume");
  const auto demos = TinyDemos(dir);
  PpoOptions o = SmallOptions();
  o.num_envs = 8;
  o.epochs = 3;
  o.eval_every = 2;
  o.eval_episodes = 6;
  o.target_success = 1.01;
  o.max_iterations = 4;
  o.threads = 1;
  const PpoReport whole =
      TrainPpo(task, demos, dir / "a" / "teacher.pt", o, CheckpointMode::kStartOver);
  o.max_iterations = 2;
  o.threads = 2;
  const PpoReport first =
      TrainPpo(task, demos, dir / "b" / "teacher.pt", o, CheckpointMode::kStartOver);
  EXPECT_EQ(first.iterations, 2);
  o.max_iterations = 4;
  const PpoReport second = TrainPpo(task, demos, dir / "b" / "teacher.pt", o);
  EXPECT_EQ(second.resumed_from, 2);
  EXPECT_EQ(second.iterations, 4);
  EXPECT_GT(whole.demo_steps, 0);

  const auto a = ReadCsv(whole.curve_csv), b = ReadCsv(second.curve_csv);
  ASSERT_EQ(a.size(), 5u);
  ASSERT_EQ(b.size(), 5u);
  for (std::size_t i = 0; i < a.size(); ++i)
    for (int c : {0, 1, 3, 4, 5, 6, 7, 8, 9})  // all but wall-clock and throughput
      EXPECT_EQ(a[i][c], b[i][c]) << "row " << i << " column " << a[0][c];
  EXPECT_NE(a[4][7], "");  // the BC loss was on
  EXPECT_GT(std::stod(b[1][3]) + std::stod(b[2][3]), 0) << "no episode succeeded before the kill";
  ExpectSameWeights(dir / "a" / "teacher.pt", dir / "b" / "teacher.pt");
}

TEST(Ppo, ACheckpointOfOtherOptionsOrAJunkOneIsRefusedByName) {
  PinMathThreads(1);
  auto task = testing::ReachTask();
  const auto dir = core::testing::TestDir("ppo_test", "refuse");
  PpoOptions o = OneIteration();
  TrainPpo(task, "", dir / "t.pt", o, CheckpointMode::kStartOver);
  o.seed = 99;
  o.max_iterations = 2;
  try {
    TrainPpo(task, "", dir / "t.pt", o);
    FAIL() << "resumed a checkpoint made with another seed";
  } catch (const core::Error& e) {
    EXPECT_NE(std::string(e.what()).find("t.ckpt"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("--fresh"), std::string::npos) << e.what();
  }
  std::ofstream(dir / "t.ckpt") << "junk";
  EXPECT_THROW(
      {
        try {
          TrainPpo(task, "", dir / "t.pt", o);
        } catch (const core::Error& e) {
          EXPECT_NE(std::string(e.what()).find("t.ckpt"), std::string::npos) << e.what();
          throw;
        }
      },
      core::Error);
  EXPECT_EQ(TrainPpo(task, "", dir / "t.pt", o, CheckpointMode::kStartOver).iterations, 2);
}

// A twin rebuilt under the same path compiles to another model: its checkpoint is refused by name,
// or, when asked to, the teacher starts over; the same inputs still resume.
TEST(Ppo, ACheckpointOfAnotherModelIsRefusedOrStartedOver) {
  PinMathThreads(1);
  auto task = testing::ReachTask();
  const auto dir = core::testing::TestDir("ppo_test", "model");
  PpoOptions o = OneIteration();
  TrainPpo(task, "", dir / "t.pt", o, CheckpointMode::kStartOver);
  auto heavier =
      std::make_shared<const sim::Task>(task->spec(), [](mjModel* m, const sim::TaskIndex&) {
        for (int b = 0; b < m->nbody; ++b) m->body_mass[b] *= 1.5;
      });
  o.max_iterations = 2;
  try {
    TrainPpo(heavier, "", dir / "t.pt", o);
    FAIL() << "resumed a checkpoint made with another model under the same task name";
  } catch (const core::Error& e) {
    EXPECT_NE(std::string(e.what()).find("task_content"), std::string::npos) << e.what();
  }
  const PpoReport over = TrainPpo(heavier, "", dir / "t.pt", o, CheckpointMode::kResumeOrStartOver);
  EXPECT_EQ(over.resumed_from, 0);
  EXPECT_EQ(over.iterations, 2);
  o.max_iterations = 3;
  const PpoReport resumed =
      TrainPpo(heavier, "", dir / "t.pt", o, CheckpointMode::kResumeOrStartOver);
  EXPECT_EQ(resumed.resumed_from, 2);
  EXPECT_EQ(resumed.iterations, 3);
  // A junk checkpoint is named in the error when resuming, and set aside when asked to.
  std::ofstream(dir / "t.ckpt") << "junk";
  try {
    TrainPpo(heavier, "", dir / "t.pt", o);
    FAIL() << "resumed a junk checkpoint";
  } catch (const core::Error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find((dir / "t.ckpt").string()), std::string::npos) << what;
    EXPECT_NE(what.find("--fresh"), std::string::npos) << what;
  }
  EXPECT_EQ(TrainPpo(heavier, "", dir / "t.pt", o, CheckpointMode::kResumeOrStartOver).resumed_from,
            0);
  std::filesystem::remove_all(dir);
}

// Demos remade under the same file name are other demos: their checkpoint is not resumed.
TEST(Ppo, ACheckpointOfOtherDemosUnderTheSameNameIsRefused) {
  PinMathThreads(1);
  auto task = testing::ReachTask();
  const auto dir = core::testing::TestDir("ppo_test", "remade");
  PpoOptions o = OneIteration();
  TrainPpo(task, TinyDemos(dir), dir / "t.pt", o, CheckpointMode::kStartOver);
  o.max_iterations = 2;
  const auto remade = TinyDemos(dir, 3);
  try {
    TrainPpo(task, remade, dir / "t.pt", o);
    FAIL() << "resumed a checkpoint made from other demos";
  } catch (const core::Error& e) {
    EXPECT_NE(std::string(e.what()).find("demos_content"), std::string::npos) << e.what();
  }
}

// A run directory copied elsewhere resumes: the demos are the same file content under another
// path.
TEST(Ppo, ACheckpointResumesWithTheSameDemosMovedElsewhere) {
  PinMathThreads(1);
  auto task = testing::ReachTask();
  const auto dir = core::testing::TestDir("ppo_test", "moved");
  PpoOptions o = OneIteration();
  const auto demos = TinyDemos(dir);
  TrainPpo(task, demos, dir / "t.pt", o, CheckpointMode::kStartOver);
  std::filesystem::create_directories(dir / "copy");
  std::filesystem::copy_file(demos, dir / "copy" / demos.filename());
  std::filesystem::copy_file(dir / "t.ckpt", dir / "copy" / "t.ckpt");
  o.max_iterations = 2;
  EXPECT_EQ(TrainPpo(task, dir / "copy" / demos.filename(), dir / "copy" / "t.pt", o).resumed_from,
            1);
  std::filesystem::remove_all(dir);
}

// Writes 20 of the scripted expert's episodes on the tiny reach to `out`, as sim demos (it
// stops there, within 60 attempts).
InverseDistillReport WriteExpertDemosOfTheReach(const std::filesystem::path& out) {
  InverseDistillOptions d;
  d.rollout.episodes = 60;
  d.rollout.threads = 2;
  d.successes = 20;
  std::filesystem::remove(out);
  return ExpertDemos(testing::ReachTask(), d, out);
}

// BC alone before PPO: the imitation of the operator's demos succeeds where PPO's first iteration
// without it does not. Its evaluation is the curve's row 0, and reaching the target there ends
// the run before any rollout; resumed, it stays ended.
TEST(Ppo, PretrainingOnDemosStartsPpoFromTheirImitation) {
  PinMathThreads(1);
  auto task = testing::ReachTask();
  const auto dir = core::testing::TestDir("ppo_test", "pretrain");
  const std::filesystem::path demos = dir / "expert.hdf5";
  ASSERT_EQ(WriteExpertDemosOfTheReach(demos).successes, 20);

  PpoOptions o = SmallOptions();
  o.max_iterations = 1;
  o.target_success = 1.01;
  const PpoReport plain = TrainPpo(task, demos, dir / "plain.pt", o, CheckpointMode::kStartOver);
  EXPECT_TRUE(std::isnan(plain.pretrain_eval_success));
  o.bc_pretrain_steps = 400;
  o.critic_warmup = 1;
  const PpoReport pre = TrainPpo(task, demos, dir / "pre.pt", o, CheckpointMode::kStartOver);
  EXPECT_LT(plain.best_eval_success, 0.3);
  EXPECT_GT(pre.pretrain_eval_success, 0.7) << "PPO alone: " << plain.best_eval_success;
  const auto rows = ReadCsv(pre.curve_csv);
  ASSERT_EQ(rows.size(), 3u);
  EXPECT_EQ(rows[1][0], "0");
  EXPECT_NEAR(std::stod(rows[1][4]), pre.pretrain_eval_success, 1e-5);
  EXPECT_EQ(rows[2][7], "") << "no BC loss while the critic warms up alone";

  o.target_success = 0.6;
  const PpoReport done = TrainPpo(task, demos, dir / "done.pt", o, CheckpointMode::kStartOver);
  EXPECT_EQ(done.stopped_by, "target");
  EXPECT_EQ(done.iterations, 0);
  EXPECT_DOUBLE_EQ(EvaluatePolicy(dir / "done.pt", task, EvalOptionsOf(o)).success_rate(),
                   done.best_eval_success);
  const PpoReport again = TrainPpo(task, demos, dir / "done.pt", o);
  EXPECT_EQ(again.resumed_from, 0);
  EXPECT_EQ(again.iterations, 0);
  EXPECT_EQ(again.stopped_by, "target");
}

// PPO fine-tunes a policy trained elsewhere (`train rl --init`): it starts from the policy's own
// success (same weights, same normalization), raises it, and keeps the normalization the weights
// were fitted to. Asked for BC pretraining too, or given a policy of another shape, it refuses.
TEST(Ppo, FineTunesAPolicyFromItsWeightsAndNormalization) {
  PinMathThreads(1);
  auto task = testing::ReachTask();
  const auto dir = core::testing::TestDir("ppo_test", "init");
  const std::filesystem::path demos = dir / "expert.hdf5";
  ASSERT_EQ(WriteExpertDemosOfTheReach(demos).successes, 20);
  PpoOptions o = SmallOptions();
  o.bc_pretrain_steps = 100;
  o.max_iterations = 1;
  o.critic_warmup = 1;  // the file is the imitation alone
  o.target_success = 1.01;
  TrainPpo(task, demos, dir / "imitation.pt", o, CheckpointMode::kStartOver);

  PpoOptions f = SmallOptions();
  f.init_policy = (dir / "imitation.pt").string();
  f.critic_warmup = 1;
  f.max_iterations = 10;
  f.target_success = 1.01;
  const double start = EvaluatePolicy(dir / "imitation.pt", task, EvalOptionsOf(f)).success_rate();
  const PpoReport r = TrainPpo(task, "", dir / "tuned.pt", f, CheckpointMode::kStartOver);
  EXPECT_DOUBLE_EQ(r.pretrain_eval_success, start);
  EXPECT_LT(start, 0.9);
  EXPECT_GT(r.best_eval_success, start + 0.1);
  PolicyNet imitation = LoadPolicy(dir / "imitation.pt"), tuned = LoadPolicy(dir / "tuned.pt");
  EXPECT_TRUE(torch::allclose(imitation->obs_mean, tuned->obs_mean, 1e-6, 1e-7));
  EXPECT_TRUE(torch::allclose(imitation->obs_std, tuned->obs_std, 1e-6, 1e-7));

  PpoOptions both = f;
  both.bc_pretrain_steps = 100;
  EXPECT_THROW(TrainPpo(task, demos, dir / "both.pt", both, CheckpointMode::kStartOver),
               core::ConfigError);
  PpoOptions wide = f;
  wide.hidden = 64;
  try {
    TrainPpo(task, "", dir / "wide.pt", wide, CheckpointMode::kStartOver);
    ADD_FAILURE() << "a 256-wide policy started a 64-wide run";
  } catch (const core::Error& e) {
    EXPECT_NE(std::string(e.what()).find("imitation.pt"), std::string::npos) << e.what();
  }
}

// The critic's warm-up steps the value network and leaves the policy exactly as it was.
TEST(Ppo, AValueOnlyMinibatchLeavesThePolicyUnchanged) {
  PinMathThreads(1);
  PolicyConfig config;
  config.point_features = 0;
  config.proprio_dim = 5;
  config.action_dim = sim::kDiscreteActions;
  PpoOptions o;
  o.hidden = 16;
  torch::manual_seed(4);
  PpoModel model(config, o);
  std::vector<torch::Tensor> before;
  for (const auto& p : model.params) before.push_back(p.detach().clone());
  const int n = 32;
  core::Rng rng(1, 1);
  const auto returns = torch::rand({n}) + 1;
  const MinibatchStats first = PpoMinibatch(
      model, o, torch::randn({n, 5}), torch::randint(0, sim::kDiscreteActions, {n}, torch::kLong),
      torch::zeros({n}), torch::randn({n}), returns, nullptr, rng, true);
  const std::size_t policy_params = model.policy->parameters().size();
  for (std::size_t k = 0; k < before.size(); ++k) {
    if (k < policy_params)
      EXPECT_TRUE(torch::equal(before[k], model.params[k])) << "policy parameter " << k;
    else
      EXPECT_FALSE(torch::equal(before[k], model.params[k])) << "value parameter " << k;
  }
  EXPECT_GT(first.value_loss, 0);
}

}  // namespace
}  // namespace twinforge::learn
