#include "core/log.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <sstream>

namespace twinforge::core {
namespace {

std::string Read(const std::filesystem::path& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// A run's log.txt is read while the run goes on (tail -f) and after it was killed: every line
// must be in the file as soon as it is logged, not when a buffer fills or the file is closed.
TEST(Log, TheRunsLogFileHoldsEachLineAsSoonAsItIsLogged) {
  SetupLogging("warn");
  const auto dir = std::filesystem::path(::testing::TempDir()) / "log_test";
  std::filesystem::remove_all(dir);
  AttachLogFile(dir / "log.txt");
  spdlog::info("stage 1/2 scan");
  spdlog::debug("a debug line kept in the file");
  const std::string live = Read(dir / "log.txt");
  EXPECT_NE(live.find("info stage 1/2 scan"), std::string::npos) << live;
  EXPECT_NE(live.find("debug a debug line kept in the file"), std::string::npos) << live;
  DetachLogFile();
  spdlog::info("after the run");
  EXPECT_EQ(Read(dir / "log.txt").find("after the run"), std::string::npos);
}

}  // namespace
}  // namespace twinforge::core
