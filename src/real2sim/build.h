// `twin build`: a scan directory in, a twin directory out.
//
//   twin/
//     scan.ply                 the fused scene (robot removed), for viewing and the editor
//     meshes/<segment>.ply     one mesh per segment, and static.ply for the table and the rest
//     twin.yaml                the spec: proposed here unless one is given (a person edits it)
//     scene.xml                the MJCF scene (ExportMjcf), meshes/visual/*.obj, with a camera
//                              at each scan frame's pose (scan_00, scan_01, ...)
//     task.yaml                with a task: the task, its scene this twin's
//     scan_after.ply           with a second scan: its fused scene
//     build.json               what was found: support plane, segments, boxes per part
#pragma once

#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>

#include "core/progress.h"
#include "real2sim/articulation.h"
#include "real2sim/export.h"
#include "real2sim/fusion.h"
#include "real2sim/segment.h"
#include "sim/task.h"

namespace twinforge::real2sim {

struct BuildOptions {
  FusionOptions fusion;
  SegmentOptions segment;
  ExportOptions export_options;
  ArticulationOptions articulation;
  std::optional<std::filesystem::path> spec;  // an edited twin.yaml to use instead of proposing
  // A second scan of the scene with a part moved (a drawer pulled out): the proposal gets that
  // part and its joint (scan.ply and scan_after.ply are both written).
  std::optional<std::filesystem::path> scan_after;
  // The task the twin is for: its twin recipe names the proposal's parts, joints and sites, and
  // task.yaml (the task in the twin) is written next to scene.xml.
  std::optional<sim::TaskSpec> task;
};

// The spec proposed for a segmentation: every fixture a fixed part, every movable object a free
// body, no joints or sites yet (those need a person, or a two-state scan).
TwinSpec ProposeSpec(const Segmentation& segmentation, const std::string& name);

// Builds `out` from the scan in `scan_dir`. Returns build.json's contents.
nlohmann::json BuildTwin(const std::filesystem::path& scan_dir, const std::filesystem::path& out,
                         const BuildOptions& options, core::Progress* progress = nullptr);

}  // namespace twinforge::real2sim
