// The options every command that talks to a robot takes: --reality, --token, --timeout-ms.
#pragma once

#include <CLI/CLI.hpp>
#include <string>

#include "reality/connect.h"

namespace twinforge::app {

struct RealityCli {
  std::string address = "proxy:open_drawer";
  std::string token;
  int timeout_ms = 10000;

  void Add(CLI::App* command) {
    command->add_option("--reality", address,
                        "tcp://host:port of a robot (bridge protocol), or proxy:WORLD to start a "
                        "proxy-reality world");
    command->add_option("--token", token, "shared secret, if the robot wants one");
    command->add_option("--timeout-ms", timeout_ms, "per-request timeout")
        ->check(CLI::PositiveNumber);
  }
  reality::ConnectOptions Options() const {
    return {.address = address, .token = token, .timeout = std::chrono::milliseconds(timeout_ms)};
  }
};

}  // namespace twinforge::app
