#include "real2sim/build.h"

#include "core/error.h"
#include "core/fs.h"
#include "core/log.h"
#include "real2sim/recipe.h"
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
  nlohmann::json articulation;
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
    if (options.scan_after) {
      const core::Scan after_scan = core::ReadScan(*options.scan_after);
      const Fusion after = FuseScan(after_scan, robot, options.fusion, progress);
      WriteMesh(out / "scan_after.ply", after.mesh);
      // What stands on the table, in both states (the table's own edges differ by noise).
      auto above = [&](const std::vector<Eigen::Vector3d>& points) {
        std::vector<Eigen::Vector3d> out;
        for (const auto& p : points)
          if (fusion.support.Distance(p) > options.segment.min_height) out.push_back(p);
        return out;
      };
      const FreeSpace seen_before(scan), seen_after(after_scan);
      ArticulationEstimate e = EstimateArticulation(
          above(fusion.points), above(after.points), options.articulation,
          [&](const Eigen::Vector3d& p) { return seen_after.SeenThrough(p); },
          [&](const Eigen::Vector3d& p) { return seen_before.SeenThrough(p); });
      const MovingPart moving = FindMovingPart(segmentation, e, fusion.mesh, after.mesh);
      AddMovingPart(spec, moving, e, moving.segment + "_moving", moving.segment + "_joint", out);
      articulation = {{"segment", moving.segment},
                      {"type", ToString(e.type)},
                      {"axis", {e.axis.x(), e.axis.y(), e.axis.z()}},
                      {"origin", {e.origin.x(), e.origin.y(), e.origin.z()}},
                      {"amount", e.amount},
                      {"fitness", e.fitness},
                      {"rmse", e.rmse},
                      {"moved_points", {e.moved_before.size(), e.moved_after.size()}}};
      spdlog::info("twin: {} moves in {}: {} by {:.3f}, fitness {:.2f}", moving.segment + "_moving",
                   moving.segment, ToString(e.type), e.amount, e.fitness);
    }
    if (options.task) ApplyRecipe(spec, options.task->twin, out, options.task->file);
  }
  SaveTwinSpec(out / "twin.yaml", spec);
  ExportOptions export_options = options.export_options;
  for (std::size_t i = 0; i < scan.frames.size(); ++i) {
    const auto& f = scan.frames[i];
    char name[32];
    std::snprintf(name, sizeof(name), "scan_%02zu", i);
    export_options.cameras.push_back(
        {name, f.camera_to_base,
         2 * std::atan(0.5 * f.intrinsics.height / f.intrinsics.fy) * 180 / M_PI});
  }
  const ExportReport exported = ExportMjcf(spec, out, export_options);
  if (options.task) WriteTwinTask(*options.task, out);

  nlohmann::json report = {
      {"scan", std::filesystem::absolute(scan_dir).lexically_normal().string()},
      {"frames", scan.frames.size()},
      {"robot_pixels_removed", fusion.robot_pixels},
      {"fused_triangles", fusion.mesh.triangles.size()},
      {"support",
       {{"normal",
         {fusion.support.normal.x(), fusion.support.normal.y(), fusion.support.normal.z()}},
        {"offset", fusion.support.offset}}},
      {"scene", exported.scene.string()},
      {"collision_boxes", exported.boxes},
      {"collision_voxel", exported.voxel}};
  nlohmann::json segments = nlohmann::json::array();
  for (const auto& s : segmentation.segments)
    segments.push_back({{"name", s.name},
                        {"movable", s.movable},
                        {"points", s.points.size()},
                        {"triangles", s.mesh.triangles.size()},
                        {"min", {s.min.x(), s.min.y(), s.min.z()}},
                        {"max", {s.max.x(), s.max.y(), s.max.z()}}});
  report["segments"] = segments;
  if (!articulation.is_null()) report["articulation"] = articulation;
  if (options.task) report["task"] = (out / "task.yaml").string();
  core::WriteFileAtomic(out / "build.json", report.dump(2));
  spdlog::info("twin: {} segments, scene {}", segmentation.segments.size(),
               exported.scene.string());
  return report;
}

}  // namespace twinforge::real2sim
