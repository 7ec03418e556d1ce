#include "core/log.h"

#include <gtest/gtest.h>

#include "core/fs.h"
#include "core/test_support.h"

namespace twinforge::core {
namespace {

// A run's log.txt is read while the run goes on (tail -f) and after it was killed: every line
// must be in the file as soon as it is logged, not when a buffer fills or the file is closed.
TEST(Log, TheRunsLogFileHoldsEachLineAsSoonAsItIsLogged) {
  SetupLogging("warn");
  const auto dir = testing::TestDir("log");
  AttachLogFile(dir / "log.txt");
  spdlog::info("stage 1/2 scan");
  spdlog::debug("a debug line kept in the file");
  const std::string live = ReadTextFile(dir / "log.txt");
  EXPECT_NE(live.find("info stage 1/2 scan"), std::string::npos) << live;
  EXPECT_NE(live.find("debug a debug line kept in the file"), std::string::npos) << live;
  DetachLogFile();
  spdlog::info("after the run");
  EXPECT_EQ(ReadTextFile(dir / "log.txt").find("after the run"), std::string::npos);
}

}  // namespace
}  // namespace twinforge::core
