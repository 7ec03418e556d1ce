#include "core/progress.h"

#include <gtest/gtest.h>

#include <thread>

namespace twinforge::core {
namespace {

TEST(Progress, LineShowsStageStepRateAndEta) {
  Progress progress("rl", 100, "episodes");
  progress.set_interactive(false);
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  progress.Advance(25, "success 0.40");
  const std::string line = progress.Line();
  EXPECT_NE(line.find("rl  25/100 episodes (25%)"), std::string::npos) << line;
  EXPECT_NE(line.find("/s"), std::string::npos) << line;
  EXPECT_NE(line.find("ETA"), std::string::npos) << line;
  EXPECT_NE(line.find("success 0.40"), std::string::npos) << line;
  EXPECT_GT(progress.rate(), 0.0);
}

TEST(Progress, SlowWorkShowsTheTimeEachUnitTakes) {
  Progress progress("distill", 13, "stages");
  progress.set_interactive(false);
  std::this_thread::sleep_for(std::chrono::milliseconds(2100));
  progress.Advance(1);
  const std::string line = progress.Line();
  EXPECT_NE(line.find("  0:02 each"), std::string::npos) << line;
  EXPECT_EQ(line.find("/s"), std::string::npos) << line;
  EXPECT_NE(line.find("ETA 0:2"), std::string::npos) << line;  // 12 more, about 2 s each
}

TEST(Progress, WorkThatEndsEarlyHasNoEtaWhenDone) {
  Progress progress("bc", 300, "epochs");
  progress.set_interactive(false);
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  progress.Advance(84);  // early stopping
  EXPECT_NE(progress.Line().find("ETA"), std::string::npos) << progress.Line();
  progress.Finish("valid loss 1.9");
  const std::string line = progress.Line();
  EXPECT_EQ(line.find("ETA"), std::string::npos) << line;
  EXPECT_NE(line.find("84/300 epochs (28%)"), std::string::npos) << line;
}

TEST(Progress, ResumedWorkRatesOnlyTheStepsThisSessionDid) {
  Progress progress("rl", 200, "iterations");
  progress.set_interactive(false);
  progress.ResumeAt(150);  // a checkpoint's 150 iterations, done by an earlier process
  std::this_thread::sleep_for(std::chrono::milliseconds(1100));
  progress.Set(151);
  const std::string line = progress.Line();
  EXPECT_NE(line.find("151/200 iterations (76%)"), std::string::npos) << line;
  // One iteration in about a second: 49 more take about 49 s, not the 0:00 that counting the
  // checkpoint's 150 as this session's would give.
  EXPECT_NE(line.find("  0:01 each"), std::string::npos) << line;
  const size_t eta = line.find("ETA ");
  ASSERT_NE(eta, std::string::npos) << line;
  const size_t colon = line.find(':', eta);
  const int seconds = 60 * std::stoi(line.substr(eta + 4)) + std::stoi(line.substr(colon + 1));
  EXPECT_GE(seconds, 45) << line;
  EXPECT_LE(seconds, 120) << line;  // a loaded machine oversleeps
}

TEST(Progress, UnknownTotalHasNoEta) {
  Progress progress("scan", 0, "frames");
  progress.set_interactive(false);
  progress.Advance(3);
  EXPECT_EQ(progress.Line().find("ETA"), std::string::npos);
}

TEST(Progress, FormatsDurations) {
  EXPECT_EQ(FormatDuration(62), "1:02");
  EXPECT_EQ(FormatDuration(3723), "1:02:03");
}

}  // namespace
}  // namespace twinforge::core
