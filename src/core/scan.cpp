#include "core/scan.h"

#include <cstdio>
#include <cstring>
#include <nlohmann/json.hpp>
#include <sstream>

#include "core/error.h"
#include "core/fs.h"
#include "core/image.h"

namespace twinforge::core {

using nlohmann::json;

namespace {

json IntrinsicJson(const PinholeIntrinsics& k) {
  return {{"width", k.width},
          {"height", k.height},
          {"intrinsic_matrix", {k.fx, 0.0, 0.0, 0.0, k.fy, 0.0, k.cx, k.cy, 1.0}}};
}

json ColumnMajor(const Eigen::Matrix4d& m) {
  json a = json::array();
  for (int c = 0; c < 4; ++c)
    for (int r = 0; r < 4; ++r) a.push_back(m(r, c));
  return a;
}

json RowMajor(const Eigen::Matrix4d& m) {
  json rows = json::array();
  for (int r = 0; r < 4; ++r) rows.push_back({m(r, 0), m(r, 1), m(r, 2), m(r, 3)});
  return rows;
}

std::string FrameName(std::size_t i) {
  char name[32];
  std::snprintf(name, sizeof name, "%06zu.png", i);
  return name;
}

}  // namespace

ScanWriter::ScanWriter(const std::filesystem::path& dir, std::string source, std::string robot) {
  if (std::filesystem::exists(dir / "frames.json"))
    throw IoError("scan directory " + dir.string() +
                  " already holds a scan (frames.json); choose another --out or remove it");
  EnsureDirectory(dir / "color");
  EnsureDirectory(dir / "depth");
  scan_.dir = dir;
  scan_.source = std::move(source);
  scan_.robot = std::move(robot);
}

void ScanWriter::Add(ScanFrameInfo info, const std::vector<uint8_t>& rgb,
                     const std::vector<uint16_t>& depth_mm) {
  const auto& k = info.intrinsics;
  const std::size_t n = std::size_t(k.width) * k.height;
  if (rgb.size() != 3 * n || depth_mm.size() != n)
    throw IoError("scan frame " + std::to_string(scan_.frames.size()) + " for " +
                  scan_.dir.string() + ": image sizes do not match " + std::to_string(k.width) +
                  "x" + std::to_string(k.height));
  const std::string name = FrameName(scan_.frames.size());
  info.color = "color/" + name;
  info.depth = "depth/" + name;
  WritePng(scan_.dir / info.color, Image{k.width, k.height, 3, 8, rgb});
  Image depth{k.width, k.height, 1, 16, {}};
  depth.bytes.resize(2 * n);
  std::memcpy(depth.bytes.data(), depth_mm.data(), 2 * n);
  WritePng(scan_.dir / info.depth, depth);
  scan_.frames.push_back(std::move(info));
  WriteIndex();
}

void ScanWriter::WriteIndex() const {
  json frames = json::array(), parameters = json::array();
  std::ostringstream log;
  log.precision(9);
  for (std::size_t i = 0; i < scan_.frames.size(); ++i) {
    const auto& f = scan_.frames[i];
    const Eigen::Matrix4d camera_to_base = f.camera_to_base.Matrix();
    const auto& q = f.camera_to_base.rotation;
    const auto& t = f.camera_to_base.translation;
    frames.push_back({{"color", f.color},
                      {"depth", f.depth},
                      {"stamp", f.stamp},
                      {"intrinsic", IntrinsicJson(f.intrinsics)},
                      {"camera_to_base",
                       {{"position", {t.x(), t.y(), t.z()}},
                        {"quaternion", {q.w(), q.x(), q.y(), q.z()}},
                        {"matrix", RowMajor(camera_to_base)}}},
                      {"joint_positions", f.joint_positions},
                      {"gripper_width", f.gripper_width}});
    parameters.push_back({{"class_name", "PinholeCameraParameters"},
                          {"extrinsic", ColumnMajor(camera_to_base.inverse())},
                          {"intrinsic", IntrinsicJson(f.intrinsics)},
                          {"version_major", 1},
                          {"version_minor", 0}});
    log << i << " " << i << " " << scan_.frames.size() << "\n";
    for (int r = 0; r < 4; ++r)
      log << camera_to_base(r, 0) << " " << camera_to_base(r, 1) << " " << camera_to_base(r, 2)
          << " " << camera_to_base(r, 3) << "\n";
  }
  if (!scan_.frames.empty())
    WriteFileAtomic(scan_.dir / "intrinsic.json",
                    IntrinsicJson(scan_.frames.front().intrinsics).dump(2));
  WriteFileAtomic(scan_.dir / "trajectory.json", json{{"class_name", "PinholeCameraTrajectory"},
                                                      {"parameters", parameters},
                                                      {"version_major", 1},
                                                      {"version_minor", 0}}
                                                     .dump(1));
  WriteFileAtomic(scan_.dir / "trajectory.log", log.str());
  WriteFileAtomic(scan_.dir / "frames.json", json{{"format", "twinforge-scan"},
                                                  {"version", 1},
                                                  {"source", scan_.source},
                                                  {"robot", scan_.robot},
                                                  {"depth_scale", scan_.depth_scale},
                                                  {"frames", frames}}
                                                 .dump(1));
}

Scan ReadScan(const std::filesystem::path& dir) {
  const auto file = dir / "frames.json";
  const json j = json::parse(ReadTextFile(file), nullptr, false);
  if (j.is_discarded()) throw ConfigError(file.string(), "", "not valid JSON");
  auto field = [&](const json& o, const char* key, const std::string& where) -> const json& {
    if (!o.is_object() || !o.contains(key))
      throw ConfigError(file.string(), where + key, "missing");
    return o.at(key);
  };
  Scan scan;
  scan.dir = dir;
  try {
    scan.source = j.value("source", "");
    scan.robot = j.value("robot", "panda");
    scan.depth_scale = field(j, "depth_scale", "").get<double>();
    const json& frames = field(j, "frames", "");
    for (std::size_t i = 0; i < frames.size(); ++i) {
      const json& f = frames[i];
      const std::string at = "frames[" + std::to_string(i) + "].";
      ScanFrameInfo info;
      info.color = field(f, "color", at).get<std::string>();
      info.depth = field(f, "depth", at).get<std::string>();
      info.stamp = f.value("stamp", 0.0);
      const json& k = field(f, "intrinsic", at);
      const auto m = field(k, "intrinsic_matrix", at + "intrinsic.").get<std::vector<double>>();
      if (m.size() != 9)
        throw ConfigError(file.string(), at + "intrinsic.intrinsic_matrix", "9 numbers");
      info.intrinsics = {field(k, "width", at).get<int>(),
                         field(k, "height", at).get<int>(),
                         m[0],
                         m[4],
                         m[6],
                         m[7]};
      const json& pose = field(f, "camera_to_base", at);
      const auto p = field(pose, "position", at).get<std::array<double, 3>>();
      const auto q = field(pose, "quaternion", at).get<std::array<double, 4>>();
      info.camera_to_base = {Vec3(p[0], p[1], p[2]), Quat(q[0], q[1], q[2], q[3]).normalized()};
      info.joint_positions = field(f, "joint_positions", at).get<std::array<double, 7>>();
      info.gripper_width = f.value("gripper_width", 0.0);
      if (!std::filesystem::is_regular_file(dir / info.color) ||
          !std::filesystem::is_regular_file(dir / info.depth))
        throw IoError(file.string() + ": " + at + " names " + info.color + " / " + info.depth +
                      ", which do not exist in " + dir.string());
      scan.frames.push_back(std::move(info));
    }
  } catch (const json::exception& e) {
    throw ConfigError(file.string(), "", std::string("malformed: ") + e.what());
  }
  return scan;
}

}  // namespace twinforge::core
