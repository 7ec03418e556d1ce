// Logging to the console and, once a run directory is known, to its log file.
//
// Code logs with spdlog's functions (spdlog::info(...)); this header sets the sinks up.
#pragma once

#include <spdlog/spdlog.h>

#include <filesystem>
#include <string>

namespace twinforge::core {

// Console logging at `level` ("trace".."critical", "off"). Safe to call more than once.
void SetupLogging(const std::string& level = "info");

// Also appends every message to `path` (created with its directories), e.g. runs/x/log.txt.
void AttachLogFile(const std::filesystem::path& path);

// Stops writing to the log file attached last, flushing it.
void DetachLogFile();

}  // namespace twinforge::core
