#include "app/twin_commands.h"

#include <spdlog/spdlog.h>

#include <fstream>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>

#include "app/gui_server.h"
#include "core/log.h"
#include "core/scan.h"
#include "pipeline/twin_score.h"
#include "real2sim/build.h"
#include "real2sim/calibrate/calibrate.h"
#include "reality/proxy_reality.h"

namespace twinforge::app {

namespace {

struct BuildCli {
  std::string scan, out, spec, scan_after, task;
  real2sim::BuildOptions options;
};

struct CalibrateCli {
  std::string twin, frames, out, config, solver, scan;
  int steps = 0;
  real2sim::CalibrateOptions options;
};

// The scan a twin was built from, as its build.json names it, if that is still a scan directory;
// empty otherwise.
std::filesystem::path BuiltFrom(const std::filesystem::path& twin) {
  std::ifstream file(twin / "build.json");
  if (!file) return {};
  const auto build = nlohmann::json::parse(file, nullptr, false);
  if (build.is_discarded() || !build.contains("scan") || !build["scan"].is_string()) return {};
  const std::filesystem::path scan = build["scan"].get<std::string>();
  return std::filesystem::exists(scan / "frames.json") ? scan : std::filesystem::path();
}

struct GuiCli {
  GuiOptions options;
};

struct ScoreCli {
  std::string twin, world;
  pipeline::TwinScoreOptions options;
};

}  // namespace

void AddTwinCommands(CLI::App& parent, int& exit_code) {
  auto* twin = parent.add_subcommand("twin", "build a digital twin from a scan");
  twin->require_subcommand(1);
  auto cli = std::make_shared<BuildCli>();
  auto* build = twin->add_subcommand(
      "build", "fuse a scan, segment it, propose (or apply) twin.yaml and export the MJCF scene");
  build->add_option("--scan", cli->scan, "scan directory (twinforge scan capture, docs/scan.md)")
      ->required()
      ->check(CLI::ExistingDirectory);
  build->add_option("--out", cli->out, "twin directory to write")->required();
  build->add_option("--spec", cli->spec, "an edited twin.yaml to use instead of proposing one")
      ->check(CLI::ExistingFile);
  build
      ->add_option("--scan-after", cli->scan_after,
                   "a second scan with a part moved (scan capture --operate-first): adds the "
                   "part and its joint")
      ->check(CLI::ExistingDirectory);
  build->add_option("--task", cli->task,
                    "the task the twin is for (built-in name or task.yaml): its twin recipe names "
                    "parts, joints and sites, and task.yaml is written into the twin");
  build->add_option("--voxel", cli->options.fusion.voxel, "TSDF voxel (m)")
      ->check(CLI::Range(0.001, 0.05));
  build
      ->add_option("--triangles", cli->options.segment.triangle_budget,
                   "triangle budget per segment mesh")
      ->check(CLI::PositiveNumber);
  build->callback([cli, &exit_code] {
    if (!cli->spec.empty()) cli->options.spec = cli->spec;
    if (!cli->scan_after.empty()) cli->options.scan_after = cli->scan_after;
    if (!cli->task.empty()) cli->options.task = sim::LoadTaskSpec(cli->task);
    core::Progress progress("fusion", 0, "frames");
    const auto report = real2sim::BuildTwin(cli->scan, cli->out, cli->options, &progress);
    progress.Finish();
    std::cout << report.dump(2) << "\n";
    exit_code = 0;
  });

  auto score_cli = std::make_shared<ScoreCli>();
  auto* score = twin->add_subcommand(
      "score",
      "grade a built twin against the proxy world it was scanned from (reads the hidden world: "
      "a grader, never part of the pipeline)");
  score->add_option("--twin", score_cli->twin, "twin directory (twin build --out)")
      ->required()
      ->check(CLI::ExistingDirectory);
  score->add_option("--world", score_cli->world, "proxy world (built-in name or directory)")
      ->required();
  score->callback([score_cli, &exit_code] {
    const auto result = pipeline::ScoreTwin(
        score_cli->twin, reality::ResolveWorldDir(score_cli->world), score_cli->options);
    std::cout << result.ToJson().dump(2) << "\n";
    exit_code = 0;
  });

  auto gui_cli = std::make_shared<GuiCli>();
  auto* gui = parent.add_subcommand(
      "gui",
      "the twin editor in the browser: cut parts, add joints and sites, set mass and friction, "
      "save twin.yaml and export the MJCF (served on 127.0.0.1)");
  gui->add_option("--twin", gui_cli->options.twin, "twin directory (twin build --out)")
      ->required()
      ->check(CLI::ExistingDirectory);
  gui->add_option("--port", gui_cli->options.port, "port on 127.0.0.1 (0: any free port)")
      ->check(CLI::Range(0, 65535));
  gui->add_option("--web", gui_cli->options.web,
                  "the built page (default: $TWINFORGE_WEB_DIR, else the build's web/)");
  gui->callback([gui_cli, &exit_code] {
    ServeTwinEditor(gui_cli->options);
    exit_code = 0;
  });

  auto calibrate_cli = std::make_shared<CalibrateCli>();
  auto* calibrate = parent.add_subcommand(
      "calibrate",
      "find where the robot's camera really is by rendering the twin (differentiable) against "
      "its frames; writes the twin with the camera corrected");
  calibrate->add_option("--twin", calibrate_cli->twin, "twin directory (twin build --out)")
      ->required()
      ->check(CLI::ExistingDirectory);
  calibrate
      ->add_option("--frames", calibrate_cli->frames,
                   "frames of the camera (scan camera --out, or any scan-layout directory)")
      ->required()
      ->check(CLI::ExistingDirectory);
  calibrate->add_option("--out", calibrate_cli->out, "refined twin directory to write")->required();
  calibrate
      ->add_option("--scan", calibrate_cli->scan,
                   "the scan the twin was built from, to refine its meshes against (default: the "
                   "one its build.json names, if it is still there)")
      ->check(CLI::ExistingDirectory);
  calibrate->add_option("--config", calibrate_cli->config, "calibration options (JSON/YAML)")
      ->check(CLI::ExistingFile);
  calibrate
      ->add_option("--solver", calibrate_cli->solver,
                   "gauss_newton (depth residuals, the arm weighted) or adam (depth + EMD)")
      ->check(CLI::IsMember({"gauss_newton", "adam"}));
  calibrate
      ->add_option("--iterations", calibrate_cli->steps,
                   "at most this many steps (Gauss-Newton iterations or Adam steps)")
      ->check(CLI::PositiveNumber);
  calibrate->callback([calibrate_cli, &exit_code] {
    auto& o = *calibrate_cli;
    if (!o.config.empty()) o.options = core::LoadConfig<real2sim::CalibrateOptions>(o.config);
    if (!o.solver.empty()) o.options.solver = o.solver;
    if (o.steps > 0) o.options.Steps() = o.steps;
    const sim::TaskSpec twin_task =
        sim::LoadTaskSpec((o.twin / std::filesystem::path("task.yaml")).string());
    const core::Scan frames = core::ReadScan(o.frames);
    core::Progress progress("calibrate", o.options.ProgressSteps(), "steps");
    const auto result = real2sim::CalibrateCamera(twin_task, frames, o.options, &progress);
    progress.Finish();
    real2sim::WriteCalibratedTwin(o.twin, frames, result, o.options, o.out);
    nlohmann::json report = real2sim::ToJson(result);
    const std::filesystem::path scan =
        o.scan.empty() ? BuiltFrom(o.twin) : std::filesystem::path(o.scan);
    if (o.options.mesh.iterations > 0 && !scan.empty()) {
      core::Progress mesh_progress("refine meshes", o.options.mesh.iterations, "steps");
      report["mesh"] =
          real2sim::RefineTwinMeshes(o.out, core::ReadScan(scan), o.options.mesh, &mesh_progress)
              .ToJson();
      mesh_progress.Finish();
    } else if (o.options.mesh.iterations > 0) {
      spdlog::warn("calibrate: no scan to refine the meshes against (--scan); meshes kept");
    }
    std::cout << report.dump(2) << "\n";
    exit_code = 0;
  });
}

}  // namespace twinforge::app
