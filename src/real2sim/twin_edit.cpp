#include "real2sim/twin_edit.h"

#include <tinyxml2.h>

#include <cmath>
#include <sstream>

#include "core/error.h"
#include "sim/mjcf.h"
#include "sim/model.h"
#include "sim/robot.h"
#include "sim/task.h"

namespace twinforge::real2sim {

namespace {

constexpr const char* kEditOrigin = "twin.yaml (edit)";

// Numbers for the browser: 0.1 mm is finer than any scan, and short numbers keep the JSON small.
// Dividing by the inverse step gives the double nearest the decimal, which prints short.
double Rounded(double v, double step) { return std::round(v / step) / std::round(1 / step); }

void AppendVector(core::Json& array, const Eigen::Vector3d& v, double step) {
  for (int k = 0; k < 3; ++k) array.push_back(Rounded(v[k], step));
}

const char* GeomTypeName(int type) {
  switch (type) {
    case mjGEOM_PLANE:
      return "plane";
    case mjGEOM_SPHERE:
      return "sphere";
    case mjGEOM_CAPSULE:
      return "capsule";
    case mjGEOM_ELLIPSOID:
      return "ellipsoid";
    case mjGEOM_CYLINDER:
      return "cylinder";
    case mjGEOM_BOX:
      return "box";
    case mjGEOM_MESH:
      return "mesh";
    default:
      return "other";
  }
}

std::vector<double> ParseNumbers(const char* text) {
  std::vector<double> out;
  std::istringstream in(text ? text : "");
  for (double v; in >> v;) out.push_back(v);
  return out;
}

// The twin's scene compiled with the robot where the twin's task puts it (the default robot at
// the origin when the twin has no task), at rest.
sim::ModelPtr CompileWithRobot(const std::filesystem::path& twin_dir) {
  sim::MjcfParts parts;
  sim::RobotSpec robot;
  if (std::filesystem::exists(twin_dir / "task.yaml")) {
    parts = sim::SceneWithRobot(sim::LoadTaskSpec((twin_dir / "task.yaml").string()), robot);
  } else {  // a twin not yet written as a task: the default robot at the origin
    parts.robot = sim::LoadRobotSpec(sim::DefaultRobotPath()).mjcf_path();
  }
  parts.scene = twin_dir / "scene.xml";
  return sim::LoadModelFromText(sim::AssembleMjcf(parts), parts.scene.string());
}

}  // namespace

TwinEditSession::TwinEditSession(std::filesystem::path twin_dir) : dir_(std::move(twin_dir)) {
  spec_ = LoadTwinSpec(dir_ / "twin.yaml");
  saved_ = core::ToJson(spec_);
}

bool TwinEditSession::dirty() const { return core::ToJson(spec_) != saved_; }

core::Json TwinEditSession::State() const {
  return {{"name", std::filesystem::absolute(dir_).lexically_normal().filename().string()},
          {"dir", std::filesystem::absolute(dir_).lexically_normal().string()},
          {"spec", core::ToJson(spec_)},
          {"can_undo", can_undo()},
          {"dirty", dirty()}};
}

void TwinEditSession::Propose(const core::Json& proposed) {
  core::ConfigDocument doc;
  doc.root = proposed;
  doc.file = kEditOrigin;
  TwinSpec spec = core::ReadConfig<TwinSpec>(doc);
  ValidateTwinSpec(spec, dir_, kEditOrigin);
  // A part cut down to nothing would only fail later, in the export.
  for (std::size_t i = 0; i < spec.parts.size(); ++i) {
    if (CutPart(spec.parts[i]).triangles.empty())
      throw core::ConfigError(kEditOrigin, "parts[" + std::to_string(i) + "].cuts",
                              "the cuts leave nothing of " + spec.parts[i].mesh);
  }
  undo_.push_back(std::move(spec_));
  spec_ = std::move(spec);
}

void TwinEditSession::Undo() {
  if (undo_.empty()) throw core::ConfigError(kEditOrigin, "undo", "nothing to undo");
  spec_ = std::move(undo_.back());
  undo_.pop_back();
}

std::filesystem::path TwinEditSession::Save() {
  const auto path = dir_ / "twin.yaml";
  if (!dirty()) return path;
  SaveTwinSpec(path, spec_, !backed_up_);
  backed_up_ = true;
  saved_ = core::ToJson(spec_);
  return path;
}

core::Json TwinEditSession::Export(const ExportOptions& options) {
  core::Json out;
  if (dirty()) out["saved"] = Save().string();
  ExportOptions o = options;
  if (o.cameras.empty()) o.cameras = ReadSceneCameras(dir_ / "scene.xml");
  const ExportReport report = ExportMjcf(spec_, dir_, o);
  out["scene"] = report.scene.string();
  out["boxes"] = report.boxes;

  const sim::ModelPtr model = CompileWithRobot(dir_);
  const mjModel* m = model.get();
  const sim::DataPtr data = sim::MakeData(m);
  mj_forward(m, data.get());
  const int mount = mj_name2id(m, mjOBJ_BODY, "robot_mount");
  auto on_robot = [&](int body) { return sim::InSubtree(m, body, mount); };
  std::map<int, int> mesh_index;  // MuJoCo mesh id -> index in "meshes"
  core::Json geoms = core::Json::array(), meshes = core::Json::array();
  for (int g = 0; g < m->ngeom; ++g) {
    const char* name = mj_id2name(m, mjOBJ_GEOM, g);
    const char* body = mj_id2name(m, mjOBJ_BODY, m->geom_bodyid[g]);
    double quat[4];
    mju_mat2Quat(quat, data->geom_xmat + 9 * g);
    int mesh = -1;
    if (m->geom_type[g] == mjGEOM_MESH) {
      const int id = m->geom_dataid[g];
      auto [it, added] = mesh_index.emplace(id, int(meshes.size()));
      if (added) {
        core::Json positions = core::Json::array(), indices = core::Json::array();
        const float* v = m->mesh_vert + 3 * m->mesh_vertadr[id];
        for (int i = 0; i < 3 * m->mesh_vertnum[id]; ++i) positions.push_back(Rounded(v[i], 1e-4));
        const int* f = m->mesh_face + 3 * m->mesh_faceadr[id];
        for (int i = 0; i < 3 * m->mesh_facenum[id]; ++i) indices.push_back(f[i]);
        meshes.push_back({{"positions", positions}, {"indices", indices}});
      }
      mesh = it->second;
    }
    geoms.push_back(
        {{"name", name ? name : ""},
         {"body", body ? body : ""},
         {"type", GeomTypeName(m->geom_type[g])},
         {"collision", (m->geom_contype[g] | m->geom_conaffinity[g]) != 0},
         {"robot", on_robot(m->geom_bodyid[g])},
         {"group", m->geom_group[g]},
         {"pos", std::vector<double>(data->geom_xpos + 3 * g, data->geom_xpos + 3 * g + 3)},
         {"quat", std::vector<double>(quat, quat + 4)},
         {"size", std::vector<double>(m->geom_size + 3 * g, m->geom_size + 3 * g + 3)},
         {"rgba", std::vector<float>(m->geom_rgba + 4 * g, m->geom_rgba + 4 * g + 4)},
         {"mesh", mesh}});
  }
  out["geoms"] = std::move(geoms);
  out["meshes"] = std::move(meshes);
  return out;
}

const Mesh& TwinEditSession::SourceMesh(const std::string& relative) {
  auto it = meshes_.find(relative);
  if (it == meshes_.end()) it = meshes_.emplace(relative, ReadMesh(dir_ / relative)).first;
  return it->second;
}

const Mesh& TwinEditSession::CutPart(const PartSpec& part) {
  const std::string key = part.mesh + core::ToJson(part.cuts).dump();
  auto it = cut_.find(key);
  if (it == cut_.end()) {
    Mesh mesh = SourceMesh(part.mesh);
    for (const auto& cut : part.cuts) mesh = CutMesh(mesh, cut);
    it = cut_.emplace(key, std::move(mesh)).first;
  }
  return it->second;
}

core::Json TwinEditSession::PartMeshJson(const std::string& part) {
  const PartSpec* spec = nullptr;
  for (const auto& p : spec_.parts)
    if (p.name == part) spec = &p;
  if (!spec) throw core::ConfigError(kEditOrigin, "parts", "no part named '" + part + "'");
  const Mesh& mesh = CutPart(*spec);
  // Only the vertices the remaining triangles use, renumbered.
  std::vector<int> renumber(mesh.vertices.size(), -1);
  core::Json positions = core::Json::array(), colors = core::Json::array(),
             indices = core::Json::array();
  const bool coloured = mesh.colors.size() == mesh.vertices.size();
  int used = 0;
  for (const auto& t : mesh.triangles)
    for (int k = 0; k < 3; ++k) {
      int& index = renumber[t[k]];
      if (index < 0) {
        index = used++;
        AppendVector(positions, mesh.vertices[t[k]], 1e-4);
        if (coloured) AppendVector(colors, mesh.colors[t[k]], 1e-3);
      }
      indices.push_back(index);
    }
  return {{"name", part}, {"positions", positions}, {"colors", colors}, {"indices", indices}};
}

core::Json TwinEditSession::ScanJson(int max_points) {
  const Mesh& scan = SourceMesh("scan.ply");
  const std::size_t n = scan.vertices.size();
  const std::size_t stride = std::max<std::size_t>(1, (n + max_points - 1) / max_points);
  const bool coloured = scan.colors.size() == n;
  core::Json positions = core::Json::array(), colors = core::Json::array();
  for (std::size_t i = 0; i < n; i += stride) {
    AppendVector(positions, scan.vertices[i], 1e-4);
    if (coloured) AppendVector(colors, scan.colors[i], 1e-3);
  }
  return {{"positions", positions}, {"colors", colors}};
}

std::vector<ExportCamera> ReadSceneCameras(const std::filesystem::path& scene_xml) {
  std::vector<ExportCamera> cameras;
  if (!std::filesystem::exists(scene_xml)) return cameras;
  tinyxml2::XMLDocument doc;
  if (doc.LoadFile(scene_xml.c_str()) != tinyxml2::XML_SUCCESS)
    throw core::ConfigError(scene_xml.string(), "",
                            std::string("not well-formed: ") + doc.ErrorStr());
  const tinyxml2::XMLElement* world =
      doc.RootElement() ? doc.RootElement()->FirstChildElement("worldbody") : nullptr;
  for (auto* c = world ? world->FirstChildElement("camera") : nullptr; c;
       c = c->NextSiblingElement("camera")) {
    const std::vector<double> pos = ParseNumbers(c->Attribute("pos"));
    const std::vector<double> quat = ParseNumbers(c->Attribute("quat"));
    if (pos.size() != 3 || quat.size() != 4)
      throw core::ConfigError(scene_xml.string(), "camera",
                              "a camera needs pos (3 numbers) and quat (4): as ExportMjcf writes");
    ExportCamera camera;
    camera.name = c->Attribute("name") ? c->Attribute("name") : "";
    camera.pose.translation = Eigen::Vector3d(pos[0], pos[1], pos[2]);
    // ExportMjcf turned OpenCV axes into MuJoCo's by a half turn about x; undo it.
    camera.pose.rotation =
        (core::QuatFromMj(quat.data()) * core::Quat(0, 1, 0, 0).conjugate()).normalized();
    camera.fovy_deg = c->DoubleAttribute("fovy", camera.fovy_deg);
    cameras.push_back(camera);
  }
  return cameras;
}

}  // namespace twinforge::real2sim
