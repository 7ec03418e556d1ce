#include "reality/teleop.h"

#include <poll.h>
#include <termios.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstring>

#include "core/error.h"

namespace twinforge::reality {

namespace {

bool IsMove(const sim::Action& a) { return a.mode == sim::ActionMode::kDiscrete && a.index < 12; }

}  // namespace

ScriptedOperator::ScriptedOperator(const sim::Task& task, const OperatorStyle& style)
    : task_(task), style_(style), expert_(task), rng_(1) {}

void ScriptedOperator::Reset(uint64_t seed) {
  expert_.Reset();
  rng_ = core::Rng(seed, 0x0e7a);
  correction_.reset();
  keys_ = 0;
}

OperatorInput ScriptedOperator::Next(const sim::Env& env) {
  OperatorInput in;
  in.think = style_.key_time * (0.5 + rng_.Uniform());
  if (rng_.Uniform() < style_.hesitation)
    in.think += style_.pause_min + (style_.pause_max - style_.pause_min) * rng_.Uniform();
  // A person looks at the scene: done when it is done, and gives up after the task's horizon.
  if (env.Success() || keys_ >= task_.spec().horizon) {
    in.kind = OperatorInput::Kind::kDone;
    return in;
  }
  in.kind = OperatorInput::Kind::kAction;
  ++keys_;
  if (correction_) {
    in.action = *correction_;
    correction_.reset();
    return in;
  }
  in.action = expert_.Act(env, rng_);
  if (rng_.Uniform() >= style_.mistake) return in;
  // A wrong key, noticed and undone by the next one.
  if (in.action.mode == sim::ActionMode::kDiscrete) {
    if (!IsMove(in.action)) return in;  // gripper keys are pressed with care
    int wrong = static_cast<int>(rng_.Index(6));
    while (wrong == in.action.index || wrong == (in.action.index ^ 1))
      wrong = static_cast<int>(rng_.Index(6));
    in.action = sim::Action::Discrete(wrong);
    correction_ = sim::Action::Discrete(wrong ^ 1);  // +x <-> -x, ...
  } else {
    const double angle = 2 * M_PI * rng_.Uniform();
    const double size = style_.mistake_size * task_.spec().control.limits.translation;
    std::array<double, sim::kContinuousActionDim> undo{};
    undo[0] = -size * std::cos(angle);
    undo[1] = -size * std::sin(angle);
    undo[6] = in.action.value[6];
    in.action.value[0] -= undo[0];
    in.action.value[1] -= undo[1];
    correction_ = sim::Action::Continuous(undo);
  }
  return in;
}

// ---------------------------------------------------------------------------------------------

OperatorInput KeyToInput(int key, sim::ActionMode mode, double& gripper) {
  static const char kMoves[] = "wsadrfujikol";  // in the order of the discrete moves 0..11
  OperatorInput in;
  in.kind = OperatorInput::Kind::kIdle;
  if (key == '\n' || key == '\r') {
    in.kind = OperatorInput::Kind::kDone;
    return in;
  }
  if (key == 'q' || key == 3 /* Ctrl-C in raw mode */ || key == 4 /* Ctrl-D */) {
    in.kind = OperatorInput::Kind::kQuit;
    return in;
  }
  int index = -1;
  if (key == 'v') index = 12;
  if (key == 'c') index = 13;
  if (const char* p = key > 0 ? std::strchr(kMoves, key) : nullptr) index = int(p - kMoves);
  if (index < 0) return in;
  in.kind = OperatorInput::Kind::kAction;
  if (mode == sim::ActionMode::kDiscrete) {
    in.action = sim::Action::Discrete(index);
    return in;
  }
  // Continuous: a full step along one axis; the gripper command latches like a discrete one.
  std::array<double, sim::kContinuousActionDim> v{};
  if (index >= 12) gripper = index == 13 ? 1.0 : -1.0;
  if (index < 12)
    v[index / 2] = index % 2 == 0 ? 1.0 : -1.0;  // one full step, in units of the limits
  v[6] = gripper;
  in.action = sim::Action::Continuous(v);
  return in;
}

struct KeyboardOperator::Terminal {
  termios saved{};
};

KeyboardOperator::KeyboardOperator(int in_fd, std::FILE* out, sim::ActionMode mode,
                                   const sim::ActionLimits& limits)
    : in_fd_(in_fd), out_(out), mode_(mode), limits_(limits) {
  if (isatty(in_fd_)) {
    auto t = std::make_unique<Terminal>();
    if (tcgetattr(in_fd_, &t->saved) == 0) {
      termios raw = t->saved;
      raw.c_lflag &= ~(ICANON | ECHO);
      raw.c_cc[VMIN] = 1;
      raw.c_cc[VTIME] = 0;
      if (tcsetattr(in_fd_, TCSANOW, &raw) == 0) terminal_ = std::move(t);
    }
  }
  std::fprintf(out_, "%s", Help());
  std::fflush(out_);
}

KeyboardOperator::~KeyboardOperator() {
  if (terminal_) tcsetattr(in_fd_, TCSANOW, &terminal_->saved);
}

const char* KeyboardOperator::Help() {
  return "keys: w/s +x/-x  a/d +y/-y  r/f up/down  u/j roll  i/k pitch  o/l yaw  "
         "c close  v open  Enter done  q stop\n";
}

int KeyboardOperator::ReadKey() {
  for (;;) {
    unsigned char c = 0;
    const ssize_t n = ::read(in_fd_, &c, 1);
    if (n == 1) return c;
    if (n == 0) return -1;
    if (errno != EINTR) throw core::IoError(std::string("keyboard: ") + std::strerror(errno));
  }
}

OperatorInput KeyboardOperator::Next(const Observation&) {
  const int key = ReadKey();
  if (key < 0) return {OperatorInput::Kind::kQuit, {}, 0};
  OperatorInput in = KeyToInput(key, mode_, gripper_);
  if (in.kind == OperatorInput::Kind::kIdle && key != ' ') {
    std::fprintf(out_, "unknown key '%c'; %s", key >= 32 && key < 127 ? key : '?', Help());
    std::fflush(out_);
  }
  if (in.kind == OperatorInput::Kind::kAction && in.action.mode == sim::ActionMode::kContinuous)
    for (int k = 0; k < 6; ++k)
      in.action.value[k] *= k < 3 ? limits_.translation : limits_.rotation;
  return in;
}

SuccessAnswer KeyboardOperator::Judge() {
  std::fprintf(out_, "did the robot do the task? [y/n] ");
  std::fflush(out_);
  for (;;) {
    const int key = ReadKey();
    if (key == 'y' || key == 'Y') return SuccessAnswer::kSuccess;
    if (key == 'n' || key == 'N') return SuccessAnswer::kFailure;
    if (key < 0) return SuccessAnswer::kUnknown;
  }
}

OperatorRun RunOperator(Robot& robot, Operator& op, ActionClient& client, Observation& o,
                        int max_actions, bool with_frames, const BeforeAct& before_act) {
  OperatorRun run;
  for (int idle = 0; run.actions < max_actions && idle < 100000;) {
    const OperatorInput in = op.Next(o);
    run.seconds += in.think;
    if (in.kind == OperatorInput::Kind::kQuit) run.quit = true;
    if (in.kind == OperatorInput::Kind::kQuit || in.kind == OperatorInput::Kind::kDone) break;
    if (in.kind == OperatorInput::Kind::kIdle) {
      ++idle;
      continue;
    }
    if (before_act) before_act(o, in.action);
    client.Act(in.action, o);
    ++run.actions;
    o = robot.Observe(with_frames);
  }
  return run;
}

std::unique_ptr<Operator> MakeOperator(Robot& robot, const std::string& mode,
                                       const sim::TaskSpec& task) {
  if (mode == "scripted" || (mode == "auto" && robot.Info().has_operator))
    return std::make_unique<RobotOperator>(robot);
  return std::make_unique<KeyboardOperator>(STDIN_FILENO, stderr, task.control.action,
                                            task.control.limits);
}

}  // namespace twinforge::reality
