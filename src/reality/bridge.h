// The bridge: a robot (real or proxy) served over the network, and the client the pipeline uses.
//
// Request/reply over ZeroMQ (REQ/REP, TCP), each message one MessagePack map; the protocol is
// written up in docs/bridge.md so that a driver for a real arm and camera can be written against
// it (e.g. in Python with pyzmq and msgpack). The server listens on loopback unless told
// otherwise, and then requires a shared token in every request.
#pragma once

#include <atomic>
#include <chrono>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>

#include "core/error.h"
#include "reality/robot.h"

namespace twinforge::reality {

constexpr int kBridgeProtocol = 1;

// A failure talking to the other side: no reply in time, a refused token, a reply that makes no
// sense. The message names the address and the request.
class BridgeError : public core::Error {
 public:
  using core::Error::Error;
};

// Wire encodings (exposed for tests and docs).
nlohmann::json EncodeObservation(const Observation& o);
Observation DecodeObservation(const nlohmann::json& j);
nlohmann::json EncodeTargets(const sim::JointTargets& t);
sim::JointTargets DecodeTargets(const nlohmann::json& j);
nlohmann::json EncodeOperatorInput(const OperatorInput& in);
OperatorInput DecodeOperatorInput(const nlohmann::json& j);

struct ServeOptions {
  std::string bind = "127.0.0.1";
  int port = 5555;
  std::string token;  // required when `bind` is not a loopback address
};

// Serves `robot` until `stop` becomes true (checked every 100 ms) or forever.
class BridgeServer {
 public:
  BridgeServer(Robot& robot, const ServeOptions& options);
  ~BridgeServer();
  // Handles requests until `stop` is set. Errors in one request are replied to, not thrown.
  void Run(const std::atomic<bool>& stop);
  // The reply to one decoded request (what Run sends back).
  nlohmann::json Handle(const nlohmann::json& request);
  const std::string& endpoint() const { return endpoint_; }

 private:
  Robot& robot_;
  ServeOptions options_;
  std::string endpoint_;
  struct Zmq;
  std::unique_ptr<Zmq> zmq_;
  long requests_ = 0;
};

struct ClientOptions {
  std::string address = "tcp://127.0.0.1:5555";
  std::chrono::milliseconds timeout{5000};  // per request
  std::string token;
};

// A Robot on the other side of the bridge. Every call either returns the reply or throws
// BridgeError within `timeout` (a dead server never hangs the client). Nothing is resent on its
// own (a lost reply to 'act' must not move the robot twice); after a failure the connection is
// rebuilt, so the next call reaches a restarted server.
class BridgeClient : public Robot {
 public:
  explicit BridgeClient(const ClientOptions& options);
  ~BridgeClient() override;

  RobotInfo Info() override;
  Observation Observe(bool with_frames) override;
  void SendTargets(const sim::JointTargets& targets) override;
  Observation Reset(const ResetRequest& request) override;
  SuccessAnswer QuerySuccess() override;
  RgbdFrame Capture(const CaptureRequest& request) override;
  OperatorInput AskOperator() override;

 private:
  nlohmann::json Call(nlohmann::json request);
  void Connect();
  ClientOptions options_;
  struct Zmq;
  std::unique_ptr<Zmq> zmq_;
  std::optional<RobotInfo> info_;
};

// Whether `host` is a loopback address ("127.0.0.1", "localhost", "::1").
bool IsLoopback(const std::string& host);

}  // namespace twinforge::reality
