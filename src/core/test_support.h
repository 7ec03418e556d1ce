// Helpers shared by the tests.
#pragma once

#include <unistd.h>

#include <filesystem>
#include <string>

namespace twinforge::core::testing {

// A path of this test process's own under the temp directory (ctest runs test processes side
// by side): twinforge_<group>_<pid>[/<name>], with whatever an earlier run left there removed.
// Not created.
inline std::filesystem::path TestDir(const std::string& group, const std::string& name = "") {
  auto dir = std::filesystem::temp_directory_path() /
             ("twinforge_" + group + "_" + std::to_string(::getpid()));
  if (!name.empty()) dir /= name;
  std::filesystem::remove_all(dir);
  return dir;
}

}  // namespace twinforge::core::testing
