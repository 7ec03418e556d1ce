#include "real2sim/build.h"

#include "core/error.h"
#include "core/fs.h"
#include "core/log.h"
#include "sim/robot.h"

namespace twinforge::real2sim {

TwinSpec ProposeSpec(const Segmentation& segmentation, const std::string& name) {
  TwinSpec spec;
  spec.name = name;
  const Plane& s = segmentation.support;
  spec.support = {s.normal.x(), s.normal.y(), s.normal.z(), s.offset};
  for (const auto& segment : segmentation.segments) {
    PartSpec part;
    part.name = segment.name;
    part.mesh = "meshes/" + segment.name + ".ply";
    part.fixed = !segment.movable;
    // A guess a person should check: ~400 kg/m^3 over the bounds for furniture, ~0.3 kg objects.
    const Eigen::Vector3d extent = segment.max - segment.min;
    part.mass = segment.movable ? 0.3 : std::max(1.0, 400 * extent.prod());
    spec.parts.push_back(part);
  }
  return spec;
}

nlohmann::json BuildTwin(const std::filesystem::path& scan_dir, const std::filesystem::path& out,
                         const BuildOptions& options, core::Progress* progress) {
  const core::Scan scan = core::ReadScan(scan_dir);
  const sim::RobotSpec robot = sim::LoadRobotSpec(std::filesystem::path(TWINFORGE_ASSETS_DIR) /
                                                  "robots" / scan.robot / "robot.yaml");
  core::EnsureDirectory(out / "meshes");
  const Fusion fusion = FuseScan(scan, robot, options.fusion, progress);
  WriteMesh(out / "scan.ply", fusion.mesh);
  const Segmentation segmentation = SegmentScene(fusion, options.segment);
  for (const auto& segment : segmentation.segments)
    WriteMesh(out / "meshes" / (segment.name + ".ply"), segment.mesh);
  if (!segmentation.static_scene.empty())
    WriteMesh(out / "meshes" / "static.ply", segmentation.static_scene);

  TwinSpec spec;
  if (options.spec) {
    // An edited spec refers to meshes by path relative to itself; they are copied alongside.
    spec = LoadTwinSpec(*options.spec);
    const auto from = options.spec->parent_path();
    for (const auto& part : spec.parts) {
      const auto target = out / part.mesh;
      if (std::filesystem::exists(from / part.mesh) && !std::filesystem::equivalent(from, out)) {
        core::EnsureDirectory(target.parent_path());
        std::filesystem::copy_file(from / part.mesh, target,
                                   std::filesystem::copy_options::overwrite_existing);
      }
    }
  } else {
    spec = ProposeSpec(segmentation, out.filename().string());
  }
  SaveTwinSpec(out / "twin.yaml", spec);
  const ExportReport exported = ExportMjcf(spec, out, options.export_options);

  nlohmann::json report = {
      {"scan", scan_dir.string()},
      {"frames", scan.frames.size()},
      {"robot_pixels_removed", fusion.robot_pixels},
      {"fused_triangles", fusion.mesh.triangles.size()},
      {"support",
       {{"normal",
         {fusion.support.normal.x(), fusion.support.normal.y(), fusion.support.normal.z()}},
        {"offset", fusion.support.offset}}},
      {"scene", exported.scene.string()},
      {"collision_boxes", exported.boxes}};
  nlohmann::json segments = nlohmann::json::array();
  for (const auto& s : segmentation.segments)
    segments.push_back({{"name", s.name},
                        {"movable", s.movable},
                        {"points", s.points.size()},
                        {"triangles", s.mesh.triangles.size()},
                        {"min", {s.min.x(), s.min.y(), s.min.z()}},
                        {"max", {s.max.x(), s.max.y(), s.max.z()}}});
  report["segments"] = segments;
  core::WriteFileAtomic(out / "build.json", report.dump(2));
  spdlog::info("twin: {} segments, scene {}", segmentation.segments.size(),
               exported.scene.string());
  return report;
}

}  // namespace twinforge::real2sim
