#include "reality/teleop.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdio>
#include <string>

#include "reality/proxy_reality.h"

namespace twinforge::reality {
namespace {

using Kind = OperatorInput::Kind;

TEST(Keyboard, KeysMapToTheFourteenMoves) {
  double gripper = -1;
  const std::string moves = "wsadrfujikol";
  for (int i = 0; i < 12; ++i) {
    const OperatorInput in = KeyToInput(moves[i], sim::ActionMode::kDiscrete, gripper);
    ASSERT_EQ(in.kind, Kind::kAction);
    EXPECT_EQ(in.action.index, i) << moves[i];
  }
  EXPECT_EQ(KeyToInput('v', sim::ActionMode::kDiscrete, gripper).action.index, 12);
  EXPECT_EQ(KeyToInput('c', sim::ActionMode::kDiscrete, gripper).action.index, 13);
  EXPECT_EQ(KeyToInput('\n', sim::ActionMode::kDiscrete, gripper).kind, Kind::kDone);
  EXPECT_EQ(KeyToInput('q', sim::ActionMode::kDiscrete, gripper).kind, Kind::kQuit);
  EXPECT_EQ(KeyToInput('x', sim::ActionMode::kDiscrete, gripper).kind, Kind::kIdle);
  // Continuous: one axis at a time; the gripper command latches.
  OperatorInput in = KeyToInput('c', sim::ActionMode::kContinuous, gripper);
  EXPECT_EQ(in.action.value[6], 1.0);
  in = KeyToInput('f', sim::ActionMode::kContinuous, gripper);
  EXPECT_LT(in.action.value[2], 0);
  EXPECT_EQ(in.action.value[0], 0);
  EXPECT_EQ(in.action.value[6], 1.0) << "still closed";
}

TEST(Keyboard, ReadsKeysFromAStreamAndAsksAboutSuccess) {
  int fds[2];
  ASSERT_EQ(::pipe(fds), 0);
  const std::string keys = "wzi\ny";
  ASSERT_EQ(::write(fds[1], keys.data(), keys.size()), ssize_t(keys.size()));
  ::close(fds[1]);
  std::FILE* sink = std::tmpfile();
  KeyboardOperator op(fds[0], sink, sim::ActionMode::kContinuous, sim::ActionLimits{0.02, 0.1});
  const Observation o;
  OperatorInput in = op.Next(o);
  ASSERT_EQ(in.kind, Kind::kAction);
  EXPECT_DOUBLE_EQ(in.action.value[0], 0.02) << "a full translation step";
  EXPECT_EQ(op.Next(o).kind, Kind::kIdle) << "'z' means nothing";
  in = op.Next(o);
  EXPECT_DOUBLE_EQ(in.action.value[4], 0.1) << "a full rotation step";
  EXPECT_EQ(op.Next(o).kind, Kind::kDone);
  EXPECT_EQ(op.Judge(), SuccessAnswer::kSuccess);
  EXPECT_EQ(op.Next(o).kind, Kind::kQuit) << "end of input";
  ::close(fds[0]);
  std::fclose(sink);
}

// The scripted operator solves the task the way a person would: a key at a time, pausing now
// and then, with wrong keys that the next key undoes; ~15 demos take a person a few minutes.
TEST(ScriptedOperator, SolvesTheTaskLikeAPersonAtAKeyboard) {
  ProxyReality proxy(ResolveWorldDir("open_drawer"));
  const sim::Task& task = proxy.hidden_env().task();
  OperatorStyle style;
  style.mistake = 0.08;
  ScriptedOperator op(task, style);
  ActionClient client(proxy, task.spec().control.limits);
  int successes = 0, mistakes = 0, pauses = 0, keys = 0;
  double seconds = 0;
  const int demos = 6;
  for (int e = 0; e < demos; ++e) {
    Observation o = proxy.Reset({static_cast<uint64_t>(40 + e), 1});
    client.ResetGripper();
    op.Reset(e);
    int previous = -1;
    for (;;) {
      const OperatorInput in = op.Next(proxy.hidden_env());
      seconds += in.think;
      pauses += in.think > 1.5 * style.key_time + 0.5 * style.pause_min;
      if (in.kind == Kind::kDone) break;
      ASSERT_EQ(in.kind, Kind::kAction);
      ++keys;
      const int key = in.action.index;
      if (previous >= 0 && previous < 12 && key == (previous ^ 1)) ++mistakes;
      previous = key;
      client.Act(in.action, o);
      o = proxy.Observe(false);
    }
    successes += proxy.QuerySuccess() == SuccessAnswer::kSuccess;
  }
  EXPECT_GE(successes, demos - 1);
  EXPECT_GE(mistakes, 2) << "wrong keys, undone";
  EXPECT_GE(pauses, 2) << "hesitations";
  const double per_demo = seconds / demos;
  EXPECT_GT(per_demo, 0.3 * keys / demos) << "a key takes a person a moment";
  EXPECT_LT(15 * per_demo, 5 * 60) << "15 demos in a few minutes";
  std::printf("operator: %d/%d demos, %.1f keys and %.1f s per demo, %d mistakes, %d pauses\n",
              successes, demos, double(keys) / demos, per_demo, mistakes, pauses);
}

// Without mistakes there are (almost) no immediately undone keys: the count above is the
// operator's doing, not the script's.
TEST(ScriptedOperator, MistakesComeFromTheStyle) {
  ProxyReality proxy(ResolveWorldDir("open_drawer"));
  const sim::Task& task = proxy.hidden_env().task();
  auto undone = [&](double mistake) {
    OperatorStyle style;
    style.mistake = mistake;
    ScriptedOperator op(task, style);
    ActionClient client(proxy, task.spec().control.limits);
    int count = 0;
    for (int e = 0; e < 4; ++e) {
      Observation o = proxy.Reset({static_cast<uint64_t>(70 + e), 1});
      client.ResetGripper();
      op.Reset(e);
      int previous = -1;
      for (OperatorInput in = op.Next(proxy.hidden_env()); in.kind == Kind::kAction;
           in = op.Next(proxy.hidden_env())) {
        count += previous >= 0 && previous < 12 && in.action.index == (previous ^ 1);
        previous = in.action.index;
        client.Act(in.action, o);
        o = proxy.Observe(false);
      }
    }
    return count;
  };
  EXPECT_GT(undone(0.15), undone(0.0) + 3);
}

}  // namespace
}  // namespace twinforge::reality
