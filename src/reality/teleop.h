// Teleoperation: the person who drives the robot while demos are recorded.
//
// Two kinds of person. A real user at a terminal (KeyboardOperator: one key per move, RialTo's
// 14 discrete moves). And, for the proxy reality, a scripted operator who watches the hidden
// scene the way a person watches the real one and types like one: a key at a time, with pauses
// to think, now and then a wrong key that the next key undoes (ScriptedOperator, run inside the
// proxy and reached through Robot::AskOperator).
#pragma once

#include <cstdio>
#include <functional>
#include <memory>
#include <optional>
#include <string>

#include "core/rng.h"
#include "reality/robot.h"
#include "sim/env.h"
#include "sim/expert.h"

namespace twinforge::reality {

// How a person types.
struct OperatorStyle {
  double key_time = 0.3;     // s per key, on average (keys are mostly held down to repeat)
  double hesitation = 0.06;  // chance of stopping to think before a key
  double pause_min = 0.6, pause_max = 2.5;  // s such a pause lasts
  double mistake = 0.05;      // chance that a move key is a wrong one, undone by the next key
  double mistake_size = 0.6;  // continuous actions: a wrong key's size, as a fraction of a step
  template <class A>
  void Serialize(A& a) {
    a("key_time", key_time);
    a("hesitation", hesitation);
    a("pause_min", pause_min);
    a("pause_max", pause_max);
    a("mistake", mistake);
    a("mistake_size", mistake_size);
    a.Require(key_time > 0, "key_time", "a positive time in s");
    a.Require(hesitation >= 0 && hesitation <= 1, "hesitation", "a probability");
    a.Require(pause_min >= 0 && pause_max >= pause_min, "pause_max", "pause_min <= pause_max");
    a.Require(mistake >= 0 && mistake < 0.5, "mistake", "a probability below 0.5");
  }
};

// The proxy reality's operator: sees the hidden scene, follows the world's task script (its
// expert steps) and types like a person. Says "done" once the task is done, and gives up (also
// "done") after the task's horizon.
class ScriptedOperator {
 public:
  ScriptedOperator(const sim::Task& task, const OperatorStyle& style);
  // A new demo: the script starts over; `seed` draws this demo's hesitations and mistakes.
  void Reset(uint64_t seed);
  OperatorInput Next(const sim::Env& env);
  int keys() const { return keys_; }

 private:
  const sim::Task& task_;
  OperatorStyle style_;
  sim::ScriptedExpert expert_;
  core::Rng rng_;
  std::optional<sim::Action> correction_;  // undoes the last, wrong key
  int keys_ = 0;
};

// Whoever drives the robot during recording, as the recorder sees them.
class Operator {
 public:
  virtual ~Operator() = default;
  // The next input, given what the robot reports now.
  virtual OperatorInput Next(const Observation& observation) = 0;
  // Asked when the robot cannot tell success itself (a real robot): did the demo succeed?
  virtual SuccessAnswer Judge() { return SuccessAnswer::kUnknown; }
  virtual std::string name() const = 0;
};

// The robot's own operator (the proxy reality's scripted one), over Robot::AskOperator.
class RobotOperator : public Operator {
 public:
  explicit RobotOperator(Robot& robot) : robot_(robot) {}
  OperatorInput Next(const Observation&) override { return robot_.AskOperator(); }
  std::string name() const override { return "scripted operator of " + robot_.Info().name; }

 private:
  Robot& robot_;
};

// What one run of an operator at the controls did.
struct OperatorRun {
  int actions = 0;
  double seconds = 0;  // the operator's own time (thinking, hesitating)
  bool quit = false;   // they asked to stop altogether, not just "done"
};

// Drives `robot` with `op`'s inputs through `client` from observation `o` (left at the last one)
// until the operator says done or quit, or after `max_actions`. `before_act` sees each
// observation and the action about to be sent (a recorder stores them); observations carry
// camera frames only `with_frames`.
using BeforeAct = std::function<void(const Observation&, const sim::Action&)>;
OperatorRun RunOperator(Robot& robot, Operator& op, ActionClient& client, Observation& o,
                        int max_actions, bool with_frames, const BeforeAct& before_act = nullptr);

// The operator for `mode`: "scripted" (the robot's own, Info().has_operator), "keyboard" (a
// person at this terminal) or "auto" (the robot's own when it has one, else the keyboard).
std::unique_ptr<Operator> MakeOperator(Robot& robot, const std::string& mode,
                                       const sim::TaskSpec& task);

// A person at a terminal. Keys (printed by Help()):
//   w/s +x/-x (away from / toward the robot base)   a/d +y/-y   r/f up/down
//   u/j roll   i/k pitch   o/l yaw   c close the gripper   v open it
//   Enter: the demo is done   q: stop recording (demos already saved are kept)
// Reads from `in_fd` (a terminal is switched to unbuffered, no-echo input while recording and
// restored afterwards); prompts go to `out`.
class KeyboardOperator : public Operator {
 public:
  KeyboardOperator(int in_fd, std::FILE* out, sim::ActionMode mode,
                   const sim::ActionLimits& limits);
  ~KeyboardOperator() override;
  OperatorInput Next(const Observation& observation) override;
  SuccessAnswer Judge() override;
  std::string name() const override { return "keyboard"; }
  static const char* Help();

 private:
  int ReadKey();  // -1 at end of input
  int in_fd_;
  std::FILE* out_;
  sim::ActionMode mode_;
  sim::ActionLimits limits_;
  double gripper_ = -1;  // continuous mode: the latched gripper command
  struct Terminal;
  std::unique_ptr<Terminal> terminal_;
};

// The input a key stands for (KeyboardOperator's map); kIdle for keys that mean nothing.
// Continuous moves are +-1 on one axis, in steps (KeyboardOperator scales them by its limits).
OperatorInput KeyToInput(int key, sim::ActionMode mode, double& gripper);

}  // namespace twinforge::reality
