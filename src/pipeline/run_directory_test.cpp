#include "pipeline/run_directory.h"

#include <gtest/gtest.h>

#include <fstream>

#include "core/config.h"
#include "core/error.h"
#include "core/fs.h"
#include "pipeline/main_job.h"

namespace twinforge::pipeline {
namespace {

std::filesystem::path FreshDir(const std::string& name) {
  const auto dir = std::filesystem::temp_directory_path() / name;
  std::filesystem::remove_all(dir);
  return dir;
}

TEST(RunDirectory, StageIsSkippedOnlyWhenInputsAndOutputsAreUnchanged) {
  const auto dir = FreshDir("twinforge_run_dir_test");
  {
    RunDirectory run(dir);
    EXPECT_FALSE(run.UpToDate("bc", "abc"));
    core::WriteFileAtomic(run / "policies/bc.pt", "weights");
    run.Record("bc", {"abc", {"policies/bc.pt"}, 1.5, ""});
    EXPECT_TRUE(run.UpToDate("bc", "abc"));
    EXPECT_FALSE(run.UpToDate("bc", "changed"));
  }
  // A new process (resume) sees the same manifest.
  RunDirectory resumed(dir);
  EXPECT_TRUE(resumed.UpToDate("bc", "abc"));
  std::filesystem::remove(dir / "policies/bc.pt");
  EXPECT_FALSE(resumed.UpToDate("bc", "abc"));
  EXPECT_TRUE(std::filesystem::exists(dir / "log.txt"));
}

TEST(RunDirectory, MalformedManifestIsAClearError) {
  const auto dir = FreshDir("twinforge_run_dir_bad");
  core::WriteFileAtomic(dir / "manifest.json", R"({"stages": {"bc": {"inputs_hash": 3}}})");
  try {
    RunDirectory run(dir);
    FAIL();
  } catch (const core::ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("manifest.json"), std::string::npos) << e.what();
  }
}

TEST(Fingerprint, ChangesWithFileContents) {
  const auto dir = FreshDir("twinforge_fingerprint");
  core::WriteFileAtomic(dir / "a.txt", "one");
  const std::string before = Fingerprint().Add("cfg").AddFile(dir / "a.txt").Hex();
  EXPECT_EQ(before, Fingerprint().Add("cfg").AddFile(dir / "a.txt").Hex());
  core::WriteFileAtomic(dir / "a.txt", "two");
  EXPECT_NE(before, Fingerprint().Add("cfg").AddFile(dir / "a.txt").Hex());
}

// The run configurations that ship (assets/runs) are valid main-job options.
TEST(RunConfigs, TheShippedOnesLoad) {
  int n = 0;
  for (const auto& e : std::filesystem::directory_iterator(TWINFORGE_ASSETS_DIR "/runs")) {
    const MainJobOptions o = core::LoadConfig<MainJobOptions>(e.path());
    EXPECT_FALSE(o.task.empty()) << e.path();
    ++n;
  }
  EXPECT_GE(n, 2);
  const auto mug = core::LoadConfig<MainJobOptions>(TWINFORGE_ASSETS_DIR "/runs/mug_on_shelf.json");
  EXPECT_EQ(mug.sim_demos, "expert");
  EXPECT_GT(mug.rl_bc_pretrain_steps, 0);
}

// The points the student sees are a run option, checked like the others.
TEST(RunConfigs, TheStudentsPointCountIsAnOption) {
  const auto o = core::ReadConfig<MainJobOptions>(
      core::ParseConfigText("distill:\n  points: 256\n", "run.yaml"));
  EXPECT_EQ(o.distill.sampling.n, 256);
  EXPECT_EQ(core::ReadConfig<MainJobOptions>(core::ParseConfigText("task: open_drawer\n", "r.yaml"))
                .distill.sampling.n,
            512);
  try {
    core::ReadConfig<MainJobOptions>(core::ParseConfigText("distill:\n  points: 4\n", "run.yaml"));
    FAIL() << "4 points accepted";
  } catch (const core::ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("points"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("run.yaml"), std::string::npos) << e.what();
  }
}

TEST(RunConfigs, DistillationIsRedoneForWhatChangesTheStudentOnly) {
  const auto options = [](const std::string& text) {
    return DistillFingerprintOptions(
        core::ReadConfig<MainJobOptions>(core::ParseConfigText(text, "run.yaml")));
  };
  const std::string defaults = options("task: open_drawer\n");
  // The form runs made before stop 70 hashed: no point count at the default.
  EXPECT_EQ(defaults.find("\"points\""), std::string::npos) << defaults;
  // Threads: the student is the same on any number (and a run's own `threads` set them).
  EXPECT_EQ(options("threads: 1\n"), defaults);
  EXPECT_EQ(options("distill:\n  threads: 1\n"), defaults);
  EXPECT_NE(options("distill:\n  points: 256\n"), defaults);
  EXPECT_NE(options("distill:\n  seed: 2\n"), defaults);
}

}  // namespace
}  // namespace twinforge::pipeline
