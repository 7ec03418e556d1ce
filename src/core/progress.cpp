#include "core/progress.h"

#include <unistd.h>

#include <cmath>
#include <cstdio>

#include "core/log.h"

namespace twinforge::core {

std::string FormatDuration(double seconds) {
  if (!std::isfinite(seconds) || seconds < 0) return "?";
  const auto total = static_cast<int64_t>(seconds + 0.5);
  const int64_t h = total / 3600, m = (total / 60) % 60, s = total % 60;
  char buffer[32];
  if (h > 0)
    std::snprintf(buffer, sizeof buffer, "%ld:%02ld:%02ld", long(h), long(m), long(s));
  else
    std::snprintf(buffer, sizeof buffer, "%ld:%02ld", long(m), long(s));
  return buffer;
}

Progress::Progress(std::string stage, int64_t total, std::string unit, double log_every_seconds)
    : stage_(std::move(stage)),
      total_(total),
      unit_(std::move(unit)),
      log_every_seconds_(log_every_seconds),
      interactive_(::isatty(STDERR_FILENO) == 1),
      start_(std::chrono::steady_clock::now()),
      last_draw_(start_),
      last_log_(start_) {}

Progress::~Progress() {
  if (!finished_) Finish();
}

double Progress::elapsed_seconds() const {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
}

double Progress::rate() const {
  const double t = elapsed_seconds();
  const int64_t steps = done_ - resumed_at_;
  return t > 0 && steps > 0 ? steps / t : 0.0;
}

std::string Progress::Line() const {
  char buffer[256];
  const double r = rate();
  std::string line = stage_ + "  " + std::to_string(done_);
  if (total_ > 0) line += "/" + std::to_string(total_);
  line += " " + unit_;
  if (total_ > 0) {
    std::snprintf(buffer, sizeof buffer, " (%.0f%%)", 100.0 * done_ / total_);
    line += buffer;
  }
  // Work that takes seconds a unit (a distillation stage, a calibration frame) reads as the time
  // each takes rather than as "0.0/s".
  if (r >= 1.0 || r == 0.0) {
    std::snprintf(buffer, sizeof buffer, "  %.1f/s", r);
    line += buffer;
  } else {
    line += "  " + FormatDuration(1.0 / r) + " each";
  }
  line += "  elapsed " + FormatDuration(elapsed_seconds());
  // Work that ended short of its total (BC stopping early) has nothing left to wait for.
  if (total_ > 0 && r > 0 && done_ < total_ && !finished_)
    line += "  ETA " + FormatDuration((total_ - done_) / r);
  if (!note_.empty()) line += "  " + note_;
  return line;
}

void Progress::Advance(int64_t n, const std::string& note) { Set(done_ + n, note); }

void Progress::Set(int64_t done, const std::string& note) {
  done_ = done;
  if (!note.empty()) note_ = note;
  Emit(false);
}

void Progress::ResumeAt(int64_t done) {
  resumed_at_ = done_ = done;
  start_ = std::chrono::steady_clock::now();
}

void Progress::Emit(bool force) {
  const auto now = std::chrono::steady_clock::now();
  if (interactive_ && (force || now - last_draw_ > std::chrono::milliseconds(200))) {
    std::fprintf(stderr, "\r\033[K%s", Line().c_str());
    std::fflush(stderr);
    last_draw_ = now;
  }
  if (!interactive_ &&
      std::chrono::duration<double>(now - last_log_).count() > log_every_seconds_) {
    spdlog::info("{}", Line());
    last_log_ = now;
  }
}

void Progress::Finish(const std::string& note) {
  if (finished_) return;
  finished_ = true;
  if (!note.empty()) note_ = note;
  if (interactive_) {
    std::fprintf(stderr, "\r\033[K");
    std::fflush(stderr);
  }
  spdlog::info("{} done: {}", stage_, Line());
}

}  // namespace twinforge::core
