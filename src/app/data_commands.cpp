#include "app/data_commands.h"

#include <unistd.h>

#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>

#include "app/reality_cli.h"
#include "core/dataset.h"
#include "core/log.h"
#include "reality/connect.h"
#include "reality/demos.h"
#include "reality/scan.h"
#include "reality/teleop.h"

namespace twinforge::app {

namespace {

struct RecordCli {
  RealityCli reality;
  std::string task = "open_drawer";
  std::string out;
  std::string op = "auto";
  reality::RecordOptions record;
};

struct ReplayCli {
  RealityCli reality;
  std::string task = "open_drawer";
  std::string demos;
};

struct ScanCli {
  RealityCli reality;
  std::string task = "open_drawer";
  std::string out;
  bool operate_first = false;
  reality::ScanOptions scan;
};

struct CameraFramesCli {
  RealityCli reality;
  std::string task = "open_drawer";
  std::string out;
  int count = reality::kCameraFrames;
  double spread = reality::kCameraFramesSpread;
  double height = reality::kCameraFramesHeight;
  uint64_t seed = 1;
};

// `auto`: the robot's own operator if it has one, else a person at this terminal.

}  // namespace

void AddDataCommands(CLI::App& parent, int& exit_code) {
  auto* demos = parent.add_subcommand("demos", "record and replay demonstrations on a robot");
  demos->require_subcommand(1);

  auto record_cli = std::make_shared<RecordCli>();
  auto* record = demos->add_subcommand(
      "record", "teleoperate the robot and save successful demos (robomimic HDF5)");
  record_cli->reality.Add(record);
  record->add_option("--task", record_cli->task, "task (built-in name or task.yaml)");
  record->add_option("--n", record_cli->record.demos, "successful demos to keep")
      ->check(CLI::PositiveNumber);
  record->add_option("--out", record_cli->out, "HDF5 file to create")->required();
  record->add_option("--level", record_cli->record.level, "reset level asked of the robot")
      ->check(CLI::Range(0, 3));
  record->add_option("--seed", record_cli->record.seed, "seed of the reset requests");
  record->add_option("--max-attempts", record_cli->record.max_attempts,
                     "give up after this many demos (default 3 x --n)");
  record
      ->add_option("--operator", record_cli->op,
                   "auto (the robot's own operator if it has one, else keyboard), scripted, "
                   "keyboard")
      ->check(CLI::IsMember({"auto", "scripted", "keyboard"}));
  record
      ->add_option("--scene-points", record_cli->record.cloud.scene_points, "scene points per step")
      ->check(CLI::PositiveNumber);
  record->add_option("--arm-points", record_cli->record.cloud.arm_points, "arm points per step")
      ->check(CLI::PositiveNumber);
  record->add_flag("--append", record_cli->record.append, "add to an existing file");
  record->callback([record_cli, &exit_code] {
    auto& o = *record_cli;
    const sim::TaskSpec task = sim::LoadTaskSpec(o.task);
    reality::RealityConnection connection(o.reality.Options());
    reality::Robot& robot = connection.robot();
    const auto op = reality::MakeOperator(robot, o.op, task);
    spdlog::info("demos: recording {} demos of {} on {} with the {}", o.record.demos, task.name,
                 robot.Info().name, op->name());
    core::Progress progress("demos", o.record.demos, "demos");
    const auto report = reality::RecordDemos(robot, *op, task, o.record, o.out, &progress);
    progress.Finish();
    std::cout << nlohmann::json{{"out", o.out},
                                {"kept", report.kept},
                                {"attempts", report.attempts},
                                {"steps", report.steps},
                                {"operator_minutes", report.operator_seconds / 60},
                                {"wall_seconds", report.wall_seconds}}
                     .dump(2)
              << "\n";
    exit_code = report.kept == o.record.demos ? 0 : 1;
  });

  auto replay_cli = std::make_shared<ReplayCli>();
  auto* replay = demos->add_subcommand(
      "replay", "send recorded demos' actions again from their recorded resets (JSON report)");
  replay_cli->reality.Add(replay);
  replay->add_option("--task", replay_cli->task, "task (built-in name or task.yaml)");
  replay->add_option("--demos", replay_cli->demos, "HDF5 file of demos")->required();
  replay->callback([replay_cli, &exit_code] {
    auto& o = *replay_cli;
    const sim::TaskSpec task = sim::LoadTaskSpec(o.task);
    const core::DatasetReader reader(o.demos);
    reality::RealityConnection connection(o.reality.Options());
    nlohmann::json results = nlohmann::json::object();
    int successes = 0;
    for (const auto& name : reader.demos()) {
      const auto answer = reality::ReplayDemo(connection.robot(), task, reader.Read(name));
      results[name] = reality::ToString(answer);
      successes += answer == reality::SuccessAnswer::kSuccess;
    }
    std::cout << nlohmann::json{{"demos", reader.demos().size()},
                                {"successes", successes},
                                {"results", results}}
                     .dump(2)
              << "\n";
    exit_code = successes == static_cast<int>(reader.demos().size()) ? 0 : 1;
  });

  auto* scan = parent.add_subcommand("scan", "RGB-D scans of the scene through the robot");
  scan->require_subcommand(1);
  auto scan_cli = std::make_shared<ScanCli>();
  auto* capture = scan->add_subcommand(
      "capture", "move the scan camera around the scene and save RGB-D frames (docs/scan.md)");
  scan_cli->reality.Add(capture);
  capture->add_option("--task", scan_cli->task, "task whose scene to scan (sets the centre)");
  capture->add_option("--out", scan_cli->out, "directory to write")->required();
  capture->add_option("--width", scan_cli->scan.width, "image width")->check(CLI::Range(16, 4096));
  capture->add_option("--height", scan_cli->scan.height, "image height")
      ->check(CLI::Range(16, 4096));
  capture->add_option("--frames-per-ring", scan_cli->scan.frames_per_ring, "views per ring")
      ->check(CLI::PositiveNumber);
  capture->add_option("--elevations", scan_cli->scan.elevations_deg, "ring elevations, degrees");
  capture->add_option("--radius", scan_cli->scan.radius, "m from the scene centre (0: auto)");
  capture->add_flag("--operate-first", scan_cli->operate_first,
                    "let the operator change the scene first (open the drawer), then send the arm "
                    "home and scan: the second state for `twin build --scan-after`");
  capture->callback([scan_cli, &exit_code] {
    auto& o = *scan_cli;
    const sim::TaskSpec task = sim::LoadTaskSpec(o.task);
    reality::RealityConnection connection(o.reality.Options());
    if (o.operate_first) {
      const auto op = reality::MakeOperator(connection.robot(), "auto", task);
      spdlog::info("scan: the {} changes the scene first", op->name());
      reality::OperateThenHome(connection.robot(), *op, task);
    }
    const auto path = reality::ScanPath(task, o.scan);
    core::Progress progress("scan", static_cast<int64_t>(path.size()), "frames");
    const core::Scan result = reality::CaptureScan(
        connection.robot(), path, reality::ScanIntrinsics(o.scan), o.out, &progress);
    progress.Finish();
    std::cout << nlohmann::json{{"out", o.out},
                                {"frames", result.frames.size()},
                                {"source", result.source}}
                     .dump(2)
              << "\n";
    exit_code = 0;
  });

  auto camera_cli = std::make_shared<CameraFramesCli>();
  auto* camera = scan->add_subcommand(
      "camera",
      "frames of the robot's fixed camera with the arm in a few poses, for `twinforge calibrate`");
  camera_cli->reality.Add(camera);
  camera->add_option("--task", camera_cli->task, "task (its robot's home pose)");
  camera->add_option("--out", camera_cli->out, "directory to write (scan layout)")->required();
  camera->add_option("--count", camera_cli->count, "frames")->check(CLI::Range(1, 100));
  camera
      ->add_option(
          "--spread", camera_cli->spread,
          "m around the point `--height` above where the camera looks, the tool is held in")
      ->check(CLI::Range(0.0, 0.3));
  camera->add_option("--height", camera_cli->height, "m above where the camera looks")
      ->check(CLI::Range(0.05, 0.6));
  camera->add_option("--seed", camera_cli->seed, "seed of the arm poses");
  camera->callback([camera_cli, &exit_code] {
    auto& o = *camera_cli;
    const sim::TaskSpec task = sim::LoadTaskSpec(o.task);
    reality::RealityConnection connection(o.reality.Options());
    const sim::RobotSpec robot =
        sim::LoadRobotSpec(reality::RobotDescriptionPath(connection.robot().Info().robot));
    core::Progress progress("camera frames", o.count, "frames");
    const Eigen::Vector3d centre =
        Eigen::Vector3d(task.camera.look_at.data()) + Eigen::Vector3d(0, 0, o.height);
    const core::Scan result =
        reality::CaptureCameraFrames(connection.robot(), sim::Kinematics(robot), centre, o.count,
                                     o.spread, o.seed, o.out, &progress);
    progress.Finish();
    std::cout << nlohmann::json{{"out", o.out}, {"frames", result.frames.size()}}.dump(2) << "\n";
    exit_code = 0;
  });
}

}  // namespace twinforge::app
