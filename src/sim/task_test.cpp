#include "sim/task.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "core/config.h"
#include "core/error.h"
#include "core/fs.h"
#include "core/test_support.h"

namespace twinforge::sim {
namespace {

// Writes a copy of the drawer task with `replace` swapped for `with` and returns the error.
std::string ErrorOfEditedDrawerTask(const std::string& replace, const std::string& with) {
  const auto source = std::filesystem::path(TWINFORGE_ASSETS_DIR) / "tasks/open_drawer";
  // One directory per test process: ctest runs these tests in parallel processes.
  const auto dir = core::testing::TestDir("task_test");
  std::filesystem::create_directories(dir);
  std::filesystem::copy_file(source / "scene.xml", dir / "scene.xml");
  std::string text = core::ReadTextFile(source / "task.yaml");
  const auto at = text.find(replace);
  EXPECT_NE(at, std::string::npos) << replace;
  text.replace(at, replace.size(), with);
  core::WriteFileAtomic(dir / "task.yaml", text);
  try {
    Task task(LoadTaskSpec((dir / "task.yaml").string()));
  } catch (const core::Error& e) {
    return e.what();
  }
  return "";
}

// A directory holding task.yaml (a twin's) loads as that task; one named like a built-in task
// but without task.yaml (a run's output) does not hide the built-in task.
TEST(Task, ADirectoryLoadsItsTaskFileAndDoesNotHideABuiltinTask) {
  const auto dir = core::testing::TestDir("task_test", "directories");
  std::filesystem::create_directories(dir / "open_drawer" / "scan");
  std::filesystem::create_directories(dir / "twin");
  const auto source = std::filesystem::path(TWINFORGE_ASSETS_DIR) / "tasks/mug_on_shelf";
  std::filesystem::copy_file(source / "task.yaml", dir / "twin" / "task.yaml");
  const auto cwd = std::filesystem::current_path();
  std::filesystem::current_path(dir);
  EXPECT_EQ(LoadTaskSpec("open_drawer").name, "open_drawer");
  EXPECT_EQ(LoadTaskSpec("twin").name, "mug_on_shelf");
  EXPECT_THROW(LoadTaskSpec("no_such_task"), core::IoError);
  std::filesystem::current_path(cwd);
  std::filesystem::remove_all(dir);
}

TEST(Task, BuiltinTasksLoad) {
  const auto names = BuiltinTasks();
  for (const char* expected :
       {"open_drawer", "open_cabinet", "mug_on_shelf", "peg_insertion", "peg_insertion_occluded",
        "peg_insertion_hidden", "spatula_flipping"})
    EXPECT_NE(std::find(names.begin(), names.end(), expected), names.end()) << expected;
  for (const auto& name : names) EXPECT_NO_THROW(Task(LoadTaskSpec(name))) << name;
}

// The movable camera's mount is a task's to set (peg_insertion_hidden's reaches the far side
// only); a task that does not set it is written as before the keys existed, so the fingerprints
// of runs made then (a run's twin stage hashes its task) stay as they were.
TEST(Task, TheCameraMountIsWrittenOnlyWhereATaskSetsIt) {
  const core::Json drawer = core::ToJson(LoadTaskSpec("open_drawer").camera);
  EXPECT_FALSE(drawer.contains("mount_azimuth"));
  EXPECT_FALSE(drawer.contains("mount_elevation"));
  const TaskSpec hidden = LoadTaskSpec("peg_insertion_hidden");
  ASSERT_TRUE(hidden.camera.mount_azimuth.has_value());
  EXPECT_EQ(*hidden.camera.mount_azimuth, (std::array<double, 2>{-0.9, 0.9}));
  EXPECT_EQ(core::ToJson(hidden.camera)["mount_elevation"], core::Json::parse("[0.8, 1.0]"));
  const std::string e =
      ErrorOfEditedDrawerTask("height: 60", "height: 60, mount_elevation: [1.0, 2.0]");
  EXPECT_NE(e.find("mount_elevation"), std::string::npos) << e;
}

TEST(Task, UnknownJointInAPredicateNamesTheField) {
  const std::string e = ErrorOfEditedDrawerTask("joint: drawer_slide, threshold: 0.12",
                                                "joint: drawer_slid, threshold: 0.12");
  EXPECT_NE(e.find("task.yaml"), std::string::npos) << e;
  EXPECT_NE(e.find("'success[0].joint'"), std::string::npos) << e;
  EXPECT_NE(e.find("no joint named 'drawer_slid'"), std::string::npos) << e;
}

TEST(Task, BadPredicateTypeListsTheChoices) {
  const std::string e = ErrorOfEditedDrawerTask("type: joint_above", "type: joint_over");
  EXPECT_NE(e.find("'success[0].type'"), std::string::npos) << e;
  EXPECT_NE(e.find("\"joint_above\""), std::string::npos) << e;
}

TEST(Task, MisspelledKeyAndBadRangeAreCaught) {
  EXPECT_NE(ErrorOfEditedDrawerTask("horizon: 80", "horizn: 80").find("did you mean 'horizon'"),
            std::string::npos);
  EXPECT_NE(ErrorOfEditedDrawerTask("x: [-0.06, 0.06]", "x: [0.06, -0.06]")
                .find("ranges written [min, max]"),
            std::string::npos);
  EXPECT_NE(ErrorOfEditedDrawerTask("bodies: [chest]", "bodies: [drawer]")
                .find("must have a free joint or be a child of the world body"),
            std::string::npos);
}

// Finger directions come in opposite pairs (a parallel gripper): an odd count is refused, by
// the step's field.
TEST(Task, AnOddNumberOfFingerDirectionsIsRefused) {
  const std::string e = ErrorOfEditedDrawerTask("offset: [-0.01, 0, 0.08], fingers: [1, 0, 0],",
                                                "offset: [-0.01, 0, 0.08], fingers: [1, 0, 0], "
                                                "symmetry: 3,");
  EXPECT_NE(e.find("'expert.steps[0].symmetry'"), std::string::npos) << e;
  EXPECT_NE(e.find("even number of finger directions"), std::string::npos) << e;
}

TEST(Task, MissingSceneFileIsNamed) {
  const std::string e = ErrorOfEditedDrawerTask("scene: scene.xml", "scene: nowhere.xml");
  EXPECT_NE(e.find("'scene'"), std::string::npos) << e;
  EXPECT_NE(e.find("nowhere.xml"), std::string::npos) << e;
}

TEST(Task, UnknownTaskNameListsBuiltins) {
  try {
    LoadTaskSpec("open_fridge");
    FAIL();
  } catch (const core::IoError& e) {
    EXPECT_NE(std::string(e.what()).find("open_drawer"), std::string::npos);
  }
}

}  // namespace
}  // namespace twinforge::sim
