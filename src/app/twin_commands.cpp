#include "app/twin_commands.h"

#include <iostream>
#include <memory>

#include "real2sim/build.h"

namespace twinforge::app {

namespace {

struct BuildCli {
  std::string scan, out, spec;
  real2sim::BuildOptions options;
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
  build->add_option("--voxel", cli->options.fusion.voxel, "TSDF voxel (m)")
      ->check(CLI::Range(0.001, 0.05));
  build
      ->add_option("--triangles", cli->options.segment.triangle_budget,
                   "triangle budget per segment mesh")
      ->check(CLI::PositiveNumber);
  build->callback([cli, &exit_code] {
    if (!cli->spec.empty()) cli->options.spec = cli->spec;
    core::Progress progress("fusion", 0, "frames");
    const auto report = real2sim::BuildTwin(cli->scan, cli->out, cli->options, &progress);
    progress.Finish();
    std::cout << report.dump(2) << "\n";
    exit_code = 0;
  });
}

}  // namespace twinforge::app
