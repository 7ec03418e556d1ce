// What twinforge's real-to-sim stage relies on from Open3D.
#pragma once

#include <string>

namespace twinforge::real2sim {

// Open3D's version, e.g. "0.16.1".
std::string Open3dVersion();

// Runs a tiny TSDF integration to prove the library works in this process; returns an empty
// string on success or what failed.
std::string Open3dSelfCheck();

}  // namespace twinforge::real2sim
