// Loading MuJoCo models with errors a user can act on, and owning them safely.
#pragma once

#include <mujoco/mujoco.h>

#include <filesystem>
#include <memory>
#include <string>

#include "core/se3.h"

namespace twinforge::sim {

struct ModelDeleter {
  void operator()(mjModel* m) const { mj_deleteModel(m); }
};
struct DataDeleter {
  void operator()(mjData* d) const { mj_deleteData(d); }
};
using ModelPtr = std::unique_ptr<mjModel, ModelDeleter>;
using DataPtr = std::unique_ptr<mjData, DataDeleter>;

// Compiles an MJCF file. Throws core::IoError if missing, core::ConfigError with MuJoCo's
// message (element, line) if it does not compile.
ModelPtr LoadModel(const std::filesystem::path& path);

// Compiles MJCF text (no relative asset paths); `origin` names it in errors.
ModelPtr LoadModelFromText(const std::string& xml, const std::string& origin = "<inline MJCF>");

DataPtr MakeData(const mjModel* m);

// Whether body `body` is `root` or hangs below it (false for the world body and for root < 1).
bool InSubtree(const mjModel* m, int body, int root);

// The body's free joint (an object), or -1.
int FreeJointOf(const mjModel* m, int body);

// Site `site`'s pose in the world frame, as `d`'s last kinematics left it.
core::Pose SiteWorldPose(const mjData* d, int site);

// "2.2.2"
std::string MujocoVersion();

}  // namespace twinforge::sim
