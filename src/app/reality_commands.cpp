#include "app/reality_commands.h"

#include <sys/prctl.h>
#include <unistd.h>

#include <atomic>
#include <csignal>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>

#include "app/reality_cli.h"
#include "reality/bridge.h"
#include "reality/proxy_reality.h"

namespace twinforge::app {

namespace {

std::atomic<bool> g_stop{false};
void RequestStop(int) { g_stop = true; }

struct ServeCli {
  std::string world;
  int parent = 0;
  reality::ServeOptions serve;
};

}  // namespace

void AddRealityCommands(CLI::App& parent, int& exit_code) {
  auto* reality = parent.add_subcommand("reality", "the robot side: proxy reality and the bridge");
  reality->require_subcommand(1);

  auto serve_cli = std::make_shared<ServeCli>();
  auto* serve = reality->add_subcommand(
      "serve", "run a proxy-reality world as a robot behind the bridge protocol (docs/bridge.md)");
  serve->add_option("--world", serve_cli->world, "world directory or built-in world name")
      ->required();
  serve->add_option("--port", serve_cli->serve.port, "TCP port");
  serve->add_option("--bind", serve_cli->serve.bind,
                    "address to listen on (not loopback: --token is required)");
  serve->add_option("--token", serve_cli->serve.token, "shared secret clients must send");
  serve->add_option("--parent", serve_cli->parent,
                    "stop when this process (the pipeline that started the server) dies");
  serve->callback([serve_cli] {
    if (serve_cli->parent > 0) {
      // A pipeline killed outright (SIGKILL) cannot stop its proxy: the kernel does.
      ::prctl(PR_SET_PDEATHSIG, SIGTERM);
      if (::getppid() != serve_cli->parent) return;  // it died before prctl took effect
    }
    reality::ProxyReality proxy(reality::ResolveWorldDir(serve_cli->world));
    reality::BridgeServer server(proxy, serve_cli->serve);
    std::signal(SIGINT, RequestStop);
    std::signal(SIGTERM, RequestStop);
    server.Run(g_stop);
  });

  auto client_cli = std::make_shared<RealityCli>();
  client_cli->address = "tcp://127.0.0.1:5555";
  auto* ping = reality->add_subcommand("ping", "ask a robot who it is and what it sees (JSON)");
  client_cli->Add(ping);
  ping->callback([client_cli, &exit_code] {
    reality::RealityConnection connection(client_cli->Options());
    reality::Robot& client = connection.robot();
    const reality::RobotInfo info = client.Info();
    const reality::Observation o = client.Observe(true);
    nlohmann::json frames = nlohmann::json::array();
    for (const auto& f : o.frames) {
      int returns = 0;
      for (uint16_t d : f.depth) returns += d > 0;
      frames.push_back({{"camera", f.camera},
                        {"width", f.intrinsics.width},
                        {"height", f.intrinsics.height},
                        {"depth_returns", returns}});
    }
    std::cout << nlohmann::json{{"name", info.name},
                                {"robot", info.robot},
                                {"control_period", info.control_period},
                                {"has_success_oracle", info.has_success_oracle},
                                {"stamp", o.stamp},
                                {"gripper_width", o.gripper_width},
                                {"ee_position",
                                 {o.ee.translation.x(), o.ee.translation.y(),
                                  o.ee.translation.z()}},
                                {"frames", frames}}
                     .dump(2)
              << "\n";
    exit_code = 0;
  });
}

}  // namespace twinforge::app
