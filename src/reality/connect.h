// Reaching reality from the pipeline by address:
//   tcp://host:port   a running bridge server: a real robot's driver, or `twinforge reality serve`
//   proxy:WORLD       a proxy-reality server started here, as its own process (`twinforge reality
//                     serve --world WORLD` on a free loopback port), stopped with the connection
// Either way the pipeline holds a BridgeClient: the proxy world stays in another process and is
// only reached through the bridge protocol.
#pragma once

#include <chrono>
#include <filesystem>
#include <memory>
#include <string>

#include "reality/bridge.h"

namespace twinforge::reality {

struct ConnectOptions {
  std::string address;
  std::string token;
  std::chrono::milliseconds timeout{10000};  // per request
  // The twinforge binary that serves proxy worlds (default: the running program).
  std::filesystem::path server_binary = "/proc/self/exe";
};

class RealityConnection {
 public:
  explicit RealityConnection(const ConnectOptions& options);
  ~RealityConnection();
  RealityConnection(const RealityConnection&) = delete;
  RealityConnection& operator=(const RealityConnection&) = delete;

  Robot& robot() { return *client_; }
  // The bridge address actually used (the child's port for proxy:WORLD).
  const std::string& address() const { return address_; }

 private:
  std::string address_;
  int child_ = -1;  // pid of the proxy server we started, if any
  std::unique_ptr<BridgeClient> client_;
};

// A TCP port on loopback that nothing listens on right now.
int FreeLoopbackPort();

}  // namespace twinforge::reality
