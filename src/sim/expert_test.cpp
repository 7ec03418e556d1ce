#include "sim/expert.h"

#include <gtest/gtest.h>

namespace twinforge::sim {
namespace {

// Each shipped expert must succeed >= 95% at level 1 in its sim scene (issue bar).
class ExpertBar : public ::testing::TestWithParam<const char*> {};

TEST_P(ExpertBar, SucceedsAtLeast95PercentAtLevel1) {
  auto task = std::make_shared<const Task>(LoadTaskSpec(GetParam()));
  const auto report = EvaluateExpert(task, 60, 1, 2024, 0.0, 2);
  EXPECT_GE(report.success_rate(), 0.95) << GetParam() << ": " << report.successes << "/60";
}

INSTANTIATE_TEST_SUITE_P(Tasks, ExpertBar, ::testing::Values("open_drawer", "open_cabinet"));

}  // namespace
}  // namespace twinforge::sim
