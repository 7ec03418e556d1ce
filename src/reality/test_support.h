// Helpers shared by the reality tests.
#pragma once

#include <unistd.h>

#include <atomic>
#include <string>
#include <thread>

#include "reality/bridge.h"
#include "reality/proxy_reality.h"

namespace twinforge::reality::testing {

// A port of this test process's own (ctest runs test processes side by side).
inline int TestPort(int k) { return 20000 + (::getpid() * 7 + k * 131) % 20000; }

// A proxy world served on loopback from a thread, for as long as the object lives.
class Served {
 public:
  explicit Served(int port, std::string token = "", const std::string& world = "open_drawer")
      : proxy_(ResolveWorldDir(world)),
        server_(proxy_, {.bind = "127.0.0.1", .port = port, .token = std::move(token)}),
        thread_([this] { server_.Run(stop_); }) {}
  ~Served() {
    stop_ = true;
    thread_.join();
  }
  ProxyReality& proxy() { return proxy_; }

 private:
  ProxyReality proxy_;
  BridgeServer server_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

inline ClientOptions Client(int port,
                            std::chrono::milliseconds timeout = std::chrono::milliseconds(5000)) {
  return {.address = "tcp://127.0.0.1:" + std::to_string(port), .timeout = timeout};
}

}  // namespace twinforge::reality::testing
