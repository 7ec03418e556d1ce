// Progress of a long job: stage, step of total, rate and ETA.
//
// On a terminal it redraws one status line on stderr (at most ~5 times a second); when stderr is
// not a terminal it stays quiet except for a log line every `log_every_seconds`, so CI logs and
// run-directory logs get a heartbeat without a flood.
#pragma once

#include <chrono>
#include <cstdint>
#include <string>

namespace twinforge::core {

class Progress {
 public:
  // `total` may be 0 when unknown (no ETA then). `unit` names a step, e.g. "episodes".
  Progress(std::string stage, int64_t total, std::string unit = "steps",
           double log_every_seconds = 30.0);
  ~Progress();

  // Advances by `n` steps; `note` (e.g. "success 0.82") is shown after the rate.
  void Advance(int64_t n = 1, const std::string& note = "");
  // Sets the absolute step count.
  void Set(int64_t done, const std::string& note = "");
  // Work resumed with `done` steps already done by an earlier process (a checkpoint): they count
  // toward the total, not toward this session's rate and ETA.
  void ResumeAt(int64_t done);
  // Ends the line and logs a summary (called by the destructor if not before).
  void Finish(const std::string& note = "");

  int64_t done() const { return done_; }
  double elapsed_seconds() const;
  // Steps per second so far in this session (0 before its first step).
  double rate() const;
  // The status line as it would be printed, e.g. "rl  120/500 episodes  12.0/s  ETA 0:31".
  std::string Line() const;

  // Overrides the terminal detection (tests).
  void set_interactive(bool interactive) { interactive_ = interactive; }

 private:
  void Emit(bool force);

  std::string stage_;
  int64_t total_;
  std::string unit_;
  double log_every_seconds_;
  int64_t done_ = 0;
  int64_t resumed_at_ = 0;  // steps done before this session (ResumeAt)
  std::string note_;
  bool interactive_;
  bool finished_ = false;
  std::chrono::steady_clock::time_point start_;
  std::chrono::steady_clock::time_point last_draw_;
  std::chrono::steady_clock::time_point last_log_;
};

// "1:02:03" / "2:03" for a duration in seconds.
std::string FormatDuration(double seconds);

}  // namespace twinforge::core
