#include "sim/expert.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <iostream>

#include "core/error.h"

namespace twinforge::sim {
namespace {

// Each shipped expert must succeed >= 95% at level 1 in its sim scene (issue bar).
class ExpertBar : public ::testing::TestWithParam<const char*> {};

TEST_P(ExpertBar, SucceedsAtLeast95PercentAtLevel1) {
  auto task = std::make_shared<const Task>(LoadTaskSpec(GetParam()));
  const auto report = EvaluateExpert(task, 100, 1, 2024, 0.0, 2);
  EXPECT_GE(report.success_rate(), 0.95) << GetParam() << ": " << report.successes << "/100";
}

INSTANTIATE_TEST_SUITE_P(Tasks, ExpertBar,
                         ::testing::Values("open_drawer", "open_cabinet", "mug_on_shelf",
                                           "peg_insertion", "peg_insertion_occluded",
                                           "peg_insertion_hidden", "spatula_flipping"));

// Planned moves (set_planning): the expert follows a trajectory optimized through the twin (iLQR,
// least joint motion over 1.5 times the steps the move needs): its first move is slower and
// steadier than the script's straight one, which starts at the full step; every planned action
// stays under the step. Every free move of the peg (above it, down to it, the lift, over the
// hole) is planned, none fails, and both episodes end with the peg in the hole. Stretched less
// (1.1), the first move takes fewer steps; a stretch under 1 is refused.
TEST(ScriptedExpert, PlannedMovesAreSteadierAndFinishThePeg) {
  auto task = std::make_shared<const Task>(LoadTaskSpec("peg_insertion"));
  const double limit = task->spec().control.limits.translation;
  for (int64_t episode = 0; episode < 2; ++episode) {
    // The translation of each action during the first move, and whether the episode succeeded.
    const auto run = [&](PlanOptions plan, ScriptedExpert& expert) {
      Env env(task);
      expert.set_planning(plan);
      core::Rng rng = BeginExpertEpisode(env, expert, 2024, episode, 1);
      std::vector<double> first_move;
      for (int t = 0; t < task->spec().horizon; ++t) {
        const Action action = expert.Act(env, rng);
        if (expert.current_step() == 0)
          first_move.push_back(Eigen::Vector3d(action.value.data()).norm());
        const StepResult r = env.Step(action);
        if (r.success) return std::make_pair(first_move, true);
        if (r.done) break;
      }
      return std::make_pair(first_move, false);
    };
    ScriptedExpert scripted(*task), planned(*task), brisk(*task);
    const auto [straight, straight_success] = run({0}, scripted);
    const auto [steady, planned_success] = run({3}, planned);
    const auto [quicker, brisk_success] = run({3, 1.1}, brisk);
    EXPECT_TRUE(straight_success && planned_success && brisk_success) << "episode " << episode;
    EXPECT_LT(quicker.size(), steady.size()) << "episode " << episode;
    ASSERT_GE(straight.size(), 3u);
    ASSERT_GE(steady.size(), 3u);
    EXPECT_GE(straight.front(), limit) << "the script's first move starts at full speed";
    EXPECT_LT(*std::max_element(steady.begin(), steady.end()), limit) << "episode " << episode;
    EXPECT_GT(steady.size(), straight.size()) << "episode " << episode;
    EXPECT_EQ(scripted.plans().planned_moves, 0);
    EXPECT_EQ(planned.plans().planned_moves, 4) << "episode " << episode;
    EXPECT_EQ(planned.plans().failed_plans, 0);
  }
  ScriptedExpert expert(*task);
  EXPECT_THROW(expert.set_planning({3, 0.9}), core::Error);
  EXPECT_THROW(expert.set_planning({-1}), core::Error);
}

// Following a plan along its path (PlanOptions::along_path), the expert aims by where the tool
// is: with the arm held still at the start of the first planned move, it asks for the same first
// step again and again, where following the plan by the clock it asks for more each step, the
// plan running on without the arm. Along the path, and arriving moving (end speed weight 0), the
// expert still puts the peg in the hole. A negative end speed weight is refused.
TEST(ScriptedExpert, AlongThePathThePlanIsFollowedFromWhereTheToolIs) {
  auto task = std::make_shared<const Task>(LoadTaskSpec("peg_insertion"));
  // The translations the expert asks for while the arm is held still for 4 steps.
  const auto held = [&](PlanOptions plan) {
    Env env(task);
    ScriptedExpert expert(*task);
    expert.set_planning(plan);
    core::Rng rng = BeginExpertEpisode(env, expert, 2024, 0, 1);
    std::vector<double> asked;
    for (int t = 0; t < 4; ++t) {
      Action action = expert.Act(env, rng);
      asked.push_back(Eigen::Vector3d(action.value.data()).norm());
      std::fill_n(action.value.begin(), 6, 0.0);
      env.Step(action);
    }
    return asked;
  };
  // Planned over 3 times the steps the move needs, a step asks for about a third of the limit.
  const std::vector<double> clock = held({3, 3.0}), path = held({3, 3.0, true});
  EXPECT_GT(clock.back(), 2 * clock.front()) << "by the clock the aim runs ahead";
  for (double step : path) EXPECT_NEAR(step, path.front(), 0.05 * path.front());
  EXPECT_NEAR(path.front(), clock.front(), 1e-9) << "at the start both aim alike";

  Env env(task);
  ScriptedExpert expert(*task);
  expert.set_planning({3, 1.0, true, 0.0});
  core::Rng rng = BeginExpertEpisode(env, expert, 2024, 1, 1);
  bool success = false;
  for (int t = 0; t < task->spec().horizon && !success; ++t) {
    const StepResult r = env.Step(expert.Act(env, rng));
    success = r.success;
    if (r.done) break;
  }
  EXPECT_TRUE(success);
  EXPECT_EQ(expert.plans().failed_plans, 0);
  EXPECT_THROW(expert.set_planning({3, 1.0, true, -1.0}), core::Error);
}

// At the limit of the 3 cm grid, turns and moves combined still close a sideways error of a
// centimetre (the mug handle needs a few mm): applying the refining moves exactly, the tool
// ends within 4 mm of a goal that no single move gets nearer to.
TEST(RefiningMove, ClosesSubGridErrors) {
  const ActionLimits limits;
  for (const Eigen::Vector3d offset :
       {Eigen::Vector3d(0.012, 0, 0), Eigen::Vector3d(0, -0.013, 0.005),
        Eigen::Vector3d(-0.01, 0.01, 0)}) {
    const core::Pose goal{offset, core::Quat::Identity()};
    core::Pose tool = core::Pose::Identity();
    for (int step = 0; step < 30; ++step) {
      const int move = RefiningMove(tool.Inverse() * goal, limits);
      if (move < 0) break;
      tool = tool * DecodeAction(Action::Discrete(move), limits, GripperState{}).delta;
    }
    EXPECT_LT((tool.translation - goal.translation).norm(), 0.004) << offset.transpose();
    EXPECT_LT(core::AngleBetween(tool.rotation, goal.rotation), 0.05) << offset.transpose();
  }
}

// A step done again because the scene changed under it (a robot's twin actor looked from over
// the hole and found the block pushed): the expert comes over the hole where the block is now and
// inserts the peg. Going straight on down from where the hole was does not. (The insertion here is
// one straight move down, as the task had it before its search: the task's own stop at the mouth
// and search would bring the peg over a block 3 cm away too.)
TEST(ScriptedExpert, RestartDoesAStepAgainWhereTheSceneIsNow) {
  TaskSpec spec = LoadTaskSpec("peg_insertion");
  const int over_hole = 4;  // "tip over the hole", the step the task marks `look`
  ASSERT_TRUE(spec.expert.steps[over_hole].look);
  ASSERT_EQ(spec.expert.steps.size(), std::size_t(over_hole + 3)) << "over, to the mouth, down";
  spec.expert.steps.erase(spec.expert.steps.begin() + over_hole + 1);
  ExpertStep& down = spec.expert.steps.back();
  down.search = 0;
  down.speed = 0.01;
  down.max_steps = 15;
  auto task = std::make_shared<const Task>(spec);
  const int block = mj_name2id(task->model(), mjOBJ_BODY, "hole_block");
  const auto run = [&](int64_t episode, bool restart) {
    Env env(task);
    ScriptedExpert expert(*task);
    core::Rng rng = BeginExpertEpisode(env, expert, 7, episode, 1);
    bool pushed = false;
    for (int t = 0; t < task->spec().horizon; ++t) {
      const int step = expert.current_step();
      Action action = expert.Act(env, rng);
      if (!pushed && step == over_hole && expert.current_step() > over_hole) {
        pushed = true;
        core::Pose pose = env.BodyPose(block);
        pose.translation.x() += 0.03;
        env.PlaceBody(block, pose);
        if (restart) {
          expert.Restart(over_hole);
          EXPECT_EQ(expert.current_step(), over_hole);
          action = expert.Act(env, rng);
        }
      }
      const StepResult r = env.Step(action);
      if (r.success) return pushed;
      if (r.done) break;
    }
    return false;
  };
  int again = 0, straight_on = 0;
  for (int64_t episode = 0; episode < 6; ++episode) {
    again += run(episode, true);
    straight_on += run(episode, false);
  }
  EXPECT_GE(again, 5) << "of 6 with the step done again";
  EXPECT_LE(straight_on, 1) << "of 6 going straight on down";
  ScriptedExpert expert(*task);
  EXPECT_THROW(expert.Restart(int(task->spec().expert.steps.size())), core::Error);
}

// The hole believed a few mm from where it is (a robot's estimate from a frame is this far off):
// the peg comes down beside the hole onto the block's top. With the task's search the expert walks
// a spiral there until the peg drops in; without it, the peg stays on top. (Misses along the
// block's y, the fingers' axis, are left out: in the twin, whose arm is stiffer than the proxy's,
// the peg was either pushed in without a search or not found with one. On the proxy the search
// finds those too: docs/samrl.md.)
TEST(ScriptedExpert, SearchFindsAHoleTheBeliefMissed) {
  const TaskSpec spec = LoadTaskSpec("peg_insertion");
  ASSERT_GT(spec.expert.steps.back().search, 0) << "the insertion step has no search";
  TaskSpec blind = spec;
  blind.expert.steps.back().search = 0;
  const Task probe(spec);
  std::vector<int> hole_sites;
  for (const char* name : {"hole_top", "hole_goal"}) {
    hole_sites.push_back(mj_name2id(probe.model(), mjOBJ_SITE, name));
    ASSERT_GE(hole_sites.back(), 0) << name;
  }
  const auto run = [&](const TaskSpec& spec, const Eigen::Vector3d& miss) {
    auto task = std::make_shared<const Task>(spec);
    int successes = 0;
    for (int64_t episode = 0; episode < 4; ++episode) {
      Env env(task);
      ScriptedExpert expert(*task);
      core::Rng rng = BeginExpertEpisode(env, expert, 11, episode, 1);
      // The hole's sites moved in the block's frame: the expert aims there.
      for (const int site : hole_sites)
        for (int k = 0; k < 3; ++k) env.mutable_model()->site_pos[3 * site + k] += miss[k];
      for (int t = 0; t < task->spec().horizon; ++t) {
        const StepResult r = env.Step(expert.Act(env, rng));
        if (r.success) {
          ++successes;
          break;
        }
        if (r.done) break;
      }
    }
    return successes;
  };
  for (const Eigen::Vector3d miss : {Eigen::Vector3d(0.003, 0, 0), Eigen::Vector3d(0.002, 0.003, 0),
                                     Eigen::Vector3d(0.004, 0.003, 0)}) {
    EXPECT_GE(run(spec, miss), 3) << "of 4 searching, the hole missed by " << miss.transpose();
    EXPECT_LE(run(blind, miss), 1) << "of 4 not searching, the hole missed by " << miss.transpose();
  }
}

// The peg is square, so the task lets the fingers take any of four directions across it and
// the hole. With only +-fingers a turn between the peg's yaw and the block's needs up to a
// quarter turn of the wrist on top of the grasp's: on the proxy joint 7 ran to its stop and the
// peg never came square to the hole (docs/samrl.md, "the wrist at its limit"). Here the block is
// turned from the peg by 1 and 1.5 rad either way: with four directions the wrist stays 0.4 rad
// from its stops (0.78 when this was written) and every episode succeeds; with two it comes
// within 0.05 rad of a stop (0.02; the twin's stiff arm still gets the peg in, the proxy's did
// not).
TEST(ScriptedExpert, TheWristTurnsToTheNearestOfTheFingerDirectionsThatServeAlike) {
  const TaskSpec spec = LoadTaskSpec("peg_insertion");
  TaskSpec two = spec;
  for (ExpertStep& step : two.expert.steps) {
    if (step.type == ExpertStepType::kMove && !step.keep_orientation)
      ASSERT_EQ(step.symmetry, 4) << "a peg step with " << step.symmetry << " finger directions";
    step.symmetry = 2;
  }
  // The closest joint 7 came to a stop (rad), and the successes, over the turns.
  const auto run = [&](const TaskSpec& spec) {
    auto task = std::make_shared<const Task>(spec);
    const mjModel* m = task->model();
    const int joint = mj_name2id(m, mjOBJ_JOINT, "joint7");
    const int peg = mj_name2id(m, mjOBJ_BODY, "peg"),
              block = mj_name2id(m, mjOBJ_BODY, "hole_block");
    EXPECT_TRUE(joint >= 0 && peg >= 0 && block >= 0);
    double margin = 1e9;
    int successes = 0, episode = 0;
    for (const double peg_yaw : {-0.5, 0.5})
      for (const double turn : {-1.5, -1.0, 1.0, 1.5}) {
        Env env(task);
        ScriptedExpert expert(*task);
        core::Rng rng = BeginExpertEpisode(env, expert, 13, episode++, 1);
        core::Pose pose = env.BodyPose(peg);
        pose.rotation = core::Yaw(peg_yaw);
        env.PlaceBody(peg, pose);
        pose = env.BodyPose(block);
        pose.rotation = core::Yaw(peg_yaw + turn);
        env.PlaceBody(block, pose);
        for (int t = 0; t < task->spec().horizon; ++t) {
          const StepResult r = env.Step(expert.Act(env, rng));
          const double q = env.data()->qpos[m->jnt_qposadr[joint]];
          margin = std::min({margin, q - m->jnt_range[2 * joint], m->jnt_range[2 * joint + 1] - q});
          if (r.success) {
            ++successes;
            break;
          }
          if (r.done) break;
        }
      }
    return std::make_pair(margin, successes);
  };
  const auto [margin4, successes4] = run(spec);
  const auto [margin2, successes2] = run(two);
  EXPECT_GT(margin4, 0.4) << "rad from joint 7's stops, four finger directions";
  EXPECT_EQ(successes4, 8) << "of 8 with four finger directions";
  EXPECT_LT(margin2, 0.05) << "rad from joint 7's stops, two finger directions";
  std::cout << "joint 7's margin: " << margin4 << " rad (four), " << margin2
            << " rad (two); successes " << successes4 << " and " << successes2 << " of 8\n";
}

}  // namespace
}  // namespace twinforge::sim
