#include "core/log.h"

#include <spdlog/sinks/basic_file_sink.h>
#include <spdlog/sinks/stdout_color_sinks.h>

#include <mutex>

#include "core/error.h"
#include "core/fs.h"

namespace twinforge::core {

namespace {
std::mutex g_mutex;
std::shared_ptr<spdlog::sinks::sink> g_file_sink;
std::shared_ptr<spdlog::sinks::sink> g_console_sink;

std::shared_ptr<spdlog::logger> Logger() {
  auto logger = spdlog::get("twinforge");
  if (!logger) {
    auto console = std::make_shared<spdlog::sinks::stderr_color_sink_mt>();
    console->set_pattern("[%H:%M:%S] %^%l%$ %v");
    g_console_sink = console;
    logger = std::make_shared<spdlog::logger>("twinforge", console);
    // Every line is flushed: a run's log file (a few hundred lines) is then written through, so
    // `tail -f` sees it live and a killed run's last lines are there; stderr writes through anyway.
    logger->flush_on(spdlog::level::trace);
    spdlog::register_logger(logger);
    spdlog::set_default_logger(logger);
  }
  return logger;
}
}  // namespace

void SetupLogging(const std::string& level) {
  std::lock_guard lock(g_mutex);
  auto logger = Logger();
  const auto parsed = spdlog::level::from_str(level);
  if (parsed == spdlog::level::off && level != "off")
    throw ConfigError(
        "", "log_level",
        "expected one of trace, debug, info, warn, error, critical, off; got \"" + level + "\"");
  // The console shows `level`; a run's log file (AttachLogFile) keeps debug lines as well.
  g_console_sink->set_level(parsed);
  logger->set_level(g_file_sink ? std::min(parsed, spdlog::level::debug) : parsed);
}

void AttachLogFile(const std::filesystem::path& path) {
  std::lock_guard lock(g_mutex);
  auto logger = Logger();
  EnsureDirectory(path.parent_path());
  // The console keeps the level it had; only the logger lets debug lines through to the file.
  if (!g_file_sink) g_console_sink->set_level(logger->level());
  if (g_file_sink) {
    auto& sinks = logger->sinks();
    sinks.erase(std::remove(sinks.begin(), sinks.end(), g_file_sink), sinks.end());
  }
  try {
    g_file_sink = std::make_shared<spdlog::sinks::basic_file_sink_mt>(path.string(), false);
  } catch (const spdlog::spdlog_ex& e) {
    throw IoError("cannot open log file " + path.string() + ": " + e.what());
  }
  g_file_sink->set_pattern("[%Y-%m-%d %H:%M:%S.%e] %l %v");
  g_file_sink->set_level(spdlog::level::debug);
  logger->sinks().push_back(g_file_sink);
  logger->set_level(std::min(logger->level(), spdlog::level::debug));
}

void DetachLogFile() {
  std::lock_guard lock(g_mutex);
  if (!g_file_sink) return;
  auto logger = Logger();
  g_file_sink->flush();
  auto& sinks = logger->sinks();
  sinks.erase(std::remove(sinks.begin(), sinks.end(), g_file_sink), sinks.end());
  g_file_sink.reset();
  logger->set_level(g_console_sink->level());
}

}  // namespace twinforge::core
