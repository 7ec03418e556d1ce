#include "sim/model.h"

#include <cstring>

#include "core/error.h"

namespace twinforge::sim {

ModelPtr LoadModel(const std::filesystem::path& path) {
  if (!std::filesystem::exists(path))
    throw core::IoError("cannot load MuJoCo model " + path.string() + ": no such file");
  char error[1024] = "";
  mjModel* m = mj_loadXML(path.c_str(), nullptr, error, sizeof error);
  if (!m) throw core::ConfigError(path.string(), "", std::string("MuJoCo rejected it: ") + error);
  return ModelPtr(m);
}

ModelPtr LoadModelFromText(const std::string& xml, const std::string& origin) {
  // The text goes through MuJoCo's virtual file system (heap-allocated: mjVFS is ~2 MB).
  auto vfs = std::make_unique<mjVFS>();
  mj_defaultVFS(vfs.get());
  const char* name = "inline_model.xml";
  if (mj_makeEmptyFileVFS(vfs.get(), name, static_cast<int>(xml.size())) != 0)
    throw core::Error("MuJoCo's virtual file system refused " + origin);
  std::memcpy(vfs->filedata[mj_findFileVFS(vfs.get(), name)], xml.data(), xml.size());
  char error[1024] = "";
  mjModel* m = mj_loadXML(name, vfs.get(), error, sizeof error);
  mj_deleteVFS(vfs.get());
  if (!m) throw core::ConfigError(origin, "", std::string("MuJoCo rejected it: ") + error);
  return ModelPtr(m);
}

DataPtr MakeData(const mjModel* m) {
  mjData* d = mj_makeData(m);
  if (!d) throw core::Error("MuJoCo could not allocate simulation data (out of memory?)");
  return DataPtr(d);
}

bool InSubtree(const mjModel* m, int body, int root) {
  if (root < 1) return false;
  for (; body > 0; body = m->body_parentid[body])
    if (body == root) return true;
  return false;
}

int FreeJointOf(const mjModel* m, int body) {
  for (int j = 0; j < m->body_jntnum[body]; ++j) {
    const int id = m->body_jntadr[body] + j;
    if (m->jnt_type[id] == mjJNT_FREE) return id;
  }
  return -1;
}

core::Pose SiteWorldPose(const mjData* d, int site) {
  core::Pose pose;
  pose.translation = Eigen::Vector3d(d->site_xpos + 3 * site);
  double quat[4];
  mju_mat2Quat(quat, d->site_xmat + 9 * site);
  pose.rotation = core::QuatFromMj(quat);
  return pose;
}

std::string MujocoVersion() {
  const int v = mj_version();  // e.g. 222
  return std::to_string(v / 100) + "." + std::to_string(v / 10 % 10) + "." + std::to_string(v % 10);
}

}  // namespace twinforge::sim
