#include "learn/distill.h"

#include <gtest/gtest.h>

#include <Eigen/Core>
#include <cmath>

#include "core/dataset.h"
#include "core/error.h"
#include "core/test_support.h"
#include "learn/policy_net.h"
#include "learn/ppo.h"
#include "learn/rollout.h"
#include "learn/test_support.h"
#include "learn/torch_runtime.h"
#include "sim/env.h"

namespace twinforge::learn {
namespace {

DistillSource Filled(const std::string& name, std::size_t steps) {
  DistillSource s;
  s.name = name;
  s.scene_n = 2;
  s.arm_n = 1;
  s.proprio_dim = 1;
  s.target_dim = 1;
  s.scene.assign(6 * steps, 0.f);
  s.arm.assign(3 * steps, 0.f);
  s.proprio.assign(steps, 0.f);
  s.target.assign(steps, 0.f);
  return s;
}

// A network whose only non-zero weights are its last layer's biases: every input gets the same
// output, with move `move` the most likely.
PolicyNet ConstantPolicy(PolicyConfig config, int move) {
  PolicyNet net(config);
  torch::NoGradGuard no_grad;
  torch::Tensor last_bias;
  for (auto& p : net->named_parameters()) {
    p.value().zero_();
    if (p.key().find("bias") != std::string::npos && p.value().dim() == 1 &&
        p.value().size(0) == config.action_dim)
      last_bias = p.value();
  }
  EXPECT_TRUE(last_bias.defined());
  for (int k = 0; k < config.action_dim; ++k) last_bias[k] = 0.1f * k;
  last_bias[move] = 3.f;
  return net;
}

TEST(Distill, CoTrainingBatchesHoldEqualSharesOfEverySource) {
  const DistillSource real = Filled("real", 15), sim = Filled("synthetic", 5000),
                      none = Filled("rendered", 0), dagger = Filled("dagger", 300);
  const std::vector<const DistillSource*> sources = {&real, &sim, &none, &dagger};
  core::Rng rng(3);
  for (int batch : {63, 64}) {
    std::vector<int> count(sources.size(), 0);
    for (const auto& [source, row] : PlanBatch(sources, batch, rng)) {  // equal weights
      ++count[source];
      EXPECT_LT(row, sources[source]->size());
    }
    EXPECT_EQ(count[2], 0);  // the empty source
    EXPECT_EQ(count[0] + count[1] + count[3], batch);
    // 15 real steps against 5000 sim steps still make a third of every batch.
    EXPECT_LE(std::abs(count[0] - count[1]), 1);
    EXPECT_LE(std::abs(count[0] - count[3]), 1);
  }
  const DistillSource empty = Filled("x", 0);
  EXPECT_THROW(PlanBatch({&empty}, 8, rng), core::Error);
}

// A real weight below 1 gives the real demos that fraction of a sim source's share.
TEST(Distill, ARealWeightScalesTheRealDemosShare) {
  const DistillSource real = Filled("real", 15), sim = Filled("synthetic", 5000),
                      dagger = Filled("dagger", 300);
  const std::vector<const DistillSource*> sources = {&real, &sim, &dagger};
  core::Rng rng(4);
  std::vector<int> count(sources.size(), 0);
  // 0.25 / 2.25 of 64 rows is 7.1: 7 real rows, 28.4 -> 28 or 29 for each sim source.
  for (const auto& [source, row] : PlanBatch(sources, 64, rng, {0.25, 1.0, 1.0})) ++count[source];
  EXPECT_EQ(count[0], 7);
  EXPECT_EQ(count[0] + count[1] + count[2], 64);
  EXPECT_LE(std::abs(count[1] - count[2]), 1);
  EXPECT_THROW(PlanBatch(sources, 64, rng, {1.0}), core::Error);
}

// The camera-pose augmentation moves the scene's points rigidly and leaves the arm's.
TEST(Distill, CameraPoseAugmentationMovesOnlyTheScenePointsRigidly) {
  core::Rng rng(2);
  std::vector<float> points;
  for (int i = 0; i < 40; ++i) {
    points.insert(points.end(), {float(rng.Uniform()), float(rng.Uniform()), float(rng.Uniform()),
                                 i % 4 == 0 ? 1.f : 0.f});
  }
  std::vector<float> moved = points;
  PerturbScene(moved.data(), 40, 0.01, 2.0, rng);
  const auto at = [](const std::vector<float>& p, int i) {
    return Eigen::Vector3d(p[4 * i], p[4 * i + 1], p[4 * i + 2]);
  };
  double largest = 0;
  for (int i = 0; i < 40; ++i) {
    if (i % 4 == 0) {
      EXPECT_EQ(at(moved, i), at(points, i)) << "arm point " << i;
      continue;
    }
    largest = std::max(largest, (at(moved, i) - at(points, i)).norm());
    for (int j = 1; j < i; ++j)  // distances between scene points are kept
      if (j % 4 != 0)
        EXPECT_NEAR((at(moved, i) - at(moved, j)).norm(), (at(points, i) - at(points, j)).norm(),
                    1e-5);
  }
  EXPECT_GT(largest, 1e-3);
  std::vector<float> same = points;
  PerturbScene(same.data(), 40, 0, 0, rng);
  EXPECT_EQ(same, points);
}

// In DAgger the student's move is sent and the teacher's distribution is stored as the label; in
// teacher rollouts the teacher's own move is sent.
TEST(Distill, DaggerSendsTheStudentsMovesAndStoresTheTeachersLabels) {
  PinMathThreads(1);
  auto task = testing::ReachTask();
  const PolicyConfig tc = testing::StatePolicyConfig(*task);
  PolicyNet teacher = ConstantPolicy(tc, 2);
  PolicyConfig sc;
  sc.points = 64;
  PolicyNet student = ConstantPolicy(sc, 9);
  DistillRollout o;
  o.keep_failures = true;
  o.sample = false;
  o.scene_points = 128;
  o.arm_points = 32;
  o.student_points = 64;
  o.threads = 2;
  const torch::Tensor label =
      torch::softmax(teacher->forward(torch::Tensor(), torch::zeros({1, tc.proprio_dim}))[0], 0);
  for (bool dagger : {true, false}) {
    const DistillCollection got =
        CollectDistill(teacher, dagger ? &student : nullptr, task, o, 0, 3);
    EXPECT_EQ(got.episodes, 3);
    EXPECT_EQ(got.kept, 3);
    const DistillSource& d = got.data;
    ASSERT_GT(d.size(), 0u);
    EXPECT_EQ(d.scene.size(), d.size() * 3 * 128);
    EXPECT_EQ(d.state.size(), d.size() * tc.proprio_dim);
    for (std::size_t t = 0; t < d.size(); ++t) {
      EXPECT_EQ(d.action[t], dagger ? 9.f : 2.f) << "step " << t;
      for (int k = 0; k < 14; ++k) EXPECT_NEAR(d.target[14 * t + k], label[k].item<float>(), 1e-6);
    }
    // The first stored state is the env's state after the episode's reset.
    sim::Env env(task);
    env.Reset(core::MixSeed(o.seed, 0), o.level);
    std::vector<float> state(tc.proprio_dim);
    env.State(state.data());
    for (int k = 0; k < tc.proprio_dim; ++k) EXPECT_EQ(d.state[k], state[k]);
  }
}

TEST(Distill, TeacherRolloutsKeepOnlyTheirSuccesses) {
  PinMathThreads(1);
  auto task = testing::ReachTask(0.2);
  torch::manual_seed(4);
  PolicyNet teacher(testing::StatePolicyConfig(*task));
  DistillRollout o;
  o.scene_points = 64;
  o.arm_points = 16;
  o.threads = 2;
  const DistillCollection got = CollectDistill(teacher, nullptr, task, o, 0, 48);
  EXPECT_GT(got.successes, 0);
  EXPECT_LT(got.successes, got.episodes);
  EXPECT_EQ(got.kept, got.successes);
  // Same data on one thread.
  o.threads = 1;
  const DistillCollection one = CollectDistill(teacher, nullptr, task, o, 0, 48);
  EXPECT_EQ(one.data.action, got.data.action);
  EXPECT_EQ(one.data.scene, got.data.scene);
}

TEST(Distill, RealDemosWithOneHotTargetsAndBadMovesNamed) {
  const auto dir = core::testing::TestDir("distill_test", "real");
  std::filesystem::remove(dir / "real.hdf5");
  {
    core::DatasetWriter w =
        core::DatasetWriter::Create(dir / "real.hdf5", {{"action_mode", "discrete"}});
    core::Episode e;
    e.actions = core::FloatArray({2, 1});
    e.actions.data = {3.f, 13.f};
    e.obs["proprio"] = core::FloatArray({2, 9});
    e.obs["scene_points"] = core::FloatArray({2, 4, 3});
    e.obs["arm_points"] = core::FloatArray({2, 2, 3});
    e.rewards = {0.f, 1.f};
    e.dones = {0, 1};
    w.Add(e, core::Split::kTrain);
    e.actions.data = {3.f, 14.f};
    w.Add(e, core::Split::kTrain);
  }
  try {
    LoadDemoSource(dir / "real.hdf5");
    FAIL() << "move 14 was accepted";
  } catch (const core::DatasetError& e) {
    EXPECT_NE(std::string(e.what()).find("demo_1/actions row 1"), std::string::npos) << e.what();
  }
}

// A teacher trained by PPO on the tiny task, distilled with small budgets: the student, seeing only
// points and proprioception, succeeds far more often than an untrained one, and DAgger ran.
TEST(Distill, TheStudentLearnsTheTeachersTask) {
  PinMathThreads(1);
  auto task = testing::ReachTask();
  const auto dir = core::testing::TestDir("distill_test", "learns");
  PpoOptions p;
  p.num_envs = 16;
  p.threads = 2;
  p.eval_every = 5;
  p.eval_episodes = 30;
  p.max_seconds = 0;
  p.max_iterations = 25;
  p.target_success = 0.8;
  const PpoReport teacher = TrainPpo(task, "", dir / "teacher.pt", p, CheckpointMode::kStartOver);
  ASSERT_GE(teacher.best_eval_success, 0.6);

  DistillOptions o;
  o.synthetic_episodes = 60;
  o.rendered_episodes = 30;
  o.distractor_episodes = 0;
  o.dagger_rounds = 1;
  o.dagger_episodes = 30;
  o.train_steps = 150;
  o.batch = 32;
  o.learning_rate = 1e-3;
  o.sampling.n = 128;
  o.hidden = 64;
  o.scene_points = 256;
  o.arm_points = 64;
  o.eval_episodes = 40;
  const DistillReport r = TrainDistill(dir / "teacher.pt", task, "", dir / "student.pt", o);
  ASSERT_EQ(r.stages.size(), 3u);
  EXPECT_EQ(r.stages[2].name, "dagger1");
  EXPECT_EQ(r.stages[2].kept, 30);  // DAgger keeps failures too
  EXPECT_EQ(r.stages[0].kept, r.stages[0].successes);

  // Scores: none for the synthetic stage (a teacher stage follows it); the rendered stage's
  // student on the DAgger round's episodes, where it acts; the last on 40 episodes of its own.
  EXPECT_EQ(r.stages[0].student, -1);
  EXPECT_DOUBLE_EQ(r.stages[1].student, r.stages[2].successes / 30.0);
  EXPECT_GE(r.stages[2].student, 0);
  // The file holds the best scored student: scored again as it was, it gets the same rate.
  PolicyNet student = LoadPolicy(dir / "student.pt");
  EXPECT_EQ(student->config().point_features, 4);
  PolicyEvalOptions eval;
  eval.episodes = 40;
  eval.seed = 9000;  // the distillation's own evaluation episodes
  eval.sample = true;
  eval.threads = 2;
  const bool last_best = r.stages[2].student > r.stages[1].student;  // a tie keeps the first
  const double best = std::max(r.stages[1].student, r.stages[2].student);
  if (last_best) {
    EXPECT_DOUBLE_EQ(EvaluatePolicy(student, task, eval).success_rate(), best);
  } else {
    PolicyNet teacher_net = LoadPolicy(dir / "teacher.pt");
    const DistillCollection again =
        CollectDistill(teacher_net, &student, task, DistillStageRollout(o, 3), 0, 30);
    EXPECT_DOUBLE_EQ(again.successes / 30.0, best);
  }
  PolicyConfig untrained_config = student->config();
  torch::manual_seed(1);
  PolicyNet untrained(untrained_config);
  const double before = EvaluatePolicy(untrained, task, eval).success_rate();
  EXPECT_GE(best, before + 0.3) << "untrained " << before;
}

// Sim-only distillation (RialTo's ablation) from a teacher that never succeeds: the teacher's
// stages leave nothing to learn from and train nothing, DAgger's relabelled steps do; without a
// DAgger round there is no data at all, and the error says why.
TEST(Distill, WithoutRealDemosOrTeacherSuccessesOnlyDAggerTrains) {
  PinMathThreads(1);
  auto task = testing::ReachTask(0.001);  // out of reach
  const auto dir = core::testing::TestDir("distill_test", "no_data");
  torch::manual_seed(2);
  PolicyNet teacher(testing::StatePolicyConfig(*task));
  SavePolicy(teacher, dir / "teacher.pt");
  DistillOptions o;
  o.synthetic_episodes = 4;
  o.rendered_episodes = 0;
  o.distractor_episodes = 0;
  o.dagger_rounds = 0;
  o.train_steps = 5;
  o.batch = 8;
  o.sampling.n = 64;
  o.hidden = 32;
  o.scene_points = 128;
  o.arm_points = 32;
  o.eval_episodes = 0;
  try {
    TrainDistill(dir / "teacher.pt", task, "", dir / "student.pt", o);
    FAIL() << "distilled from no data";
  } catch (const core::Error& e) {
    EXPECT_NE(std::string(e.what()).find("no data to train on"), std::string::npos) << e.what();
  }
  o.dagger_rounds = 1;
  o.dagger_episodes = 2;
  const DistillReport r = TrainDistill(dir / "teacher.pt", task, "", dir / "student.pt", o);
  ASSERT_EQ(r.stages.size(), 2u);
  EXPECT_EQ(r.stages[0].steps, 0);
  EXPECT_TRUE(std::isnan(r.stages[0].loss));
  EXPECT_GT(r.stages[1].steps, 0);
  EXPECT_TRUE(std::isfinite(r.stages[1].loss));
  EXPECT_TRUE(std::filesystem::exists(dir / "student.pt"));
}

}  // namespace
}  // namespace twinforge::learn
