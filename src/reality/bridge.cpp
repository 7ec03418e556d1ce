#include "reality/bridge.h"

#include <spdlog/spdlog.h>

#include <cmath>
#include <cstring>
#include <zmq.hpp>

namespace twinforge::reality {

using nlohmann::json;

namespace {

json EncodePose(const core::Pose& p) {
  const core::Quat& q = p.rotation;
  return {{"position", {p.translation.x(), p.translation.y(), p.translation.z()}},
          {"quaternion", {q.w(), q.x(), q.y(), q.z()}}};
}

// Reads field `key` of `j` or throws BridgeError naming it: replies come from other programs.
const json& Field(const json& j, const char* key) {
  if (!j.is_object() || !j.contains(key))
    throw BridgeError(std::string("message has no field '") + key + "'");
  return j.at(key);
}

std::string String(const json& j, const char* key) {
  const json& v = Field(j, key);
  if (!v.is_string()) throw BridgeError(std::string("field '") + key + "' is not a string");
  return v.get<std::string>();
}

template <class T>
T Number(const json& j, const char* key) {
  const json& v = Field(j, key);
  if (!v.is_number()) throw BridgeError(std::string("field '") + key + "' is not a number");
  return v.get<T>();
}

template <int N>
Eigen::Matrix<double, N, 1> Vector(const json& j, const char* key) {
  const json& v = Field(j, key);
  if (!v.is_array() || v.size() != N)
    throw BridgeError(std::string("field '") + key + "' is not " + std::to_string(N) + " numbers");
  Eigen::Matrix<double, N, 1> out;
  for (int i = 0; i < N; ++i) {
    if (!v[i].is_number()) throw BridgeError(std::string("field '") + key + "' has a non-number");
    out[i] = v[i].get<double>();
  }
  return out;
}

core::Pose DecodePose(const json& j) {
  const Eigen::Vector4d q = Vector<4>(j, "quaternion");
  if (!(q.norm() > 0.5)) throw BridgeError("field 'quaternion' is not a unit quaternion");
  return {Vector<3>(j, "position"), core::Quat(q[0], q[1], q[2], q[3]).normalized()};
}

const json::binary_t& Binary(const json& j, const char* key, std::size_t bytes) {
  const json& v = Field(j, key);
  if (!v.is_binary()) throw BridgeError(std::string("field '") + key + "' is not binary");
  if (v.get_binary().size() != bytes)
    throw BridgeError(std::string("field '") + key + "' has " +
                      std::to_string(v.get_binary().size()) + " bytes, expected " +
                      std::to_string(bytes));
  return v.get_binary();
}

// Intrinsics as fields of a map: a frame carries them at its top level, a capture request
// under "intrinsics".
json EncodeIntrinsics(const sim::CameraIntrinsics& k) {
  return {{"width", k.width}, {"height", k.height}, {"fx", k.fx},
          {"fy", k.fy},       {"cx", k.cx},         {"cy", k.cy}};
}

sim::CameraIntrinsics DecodeIntrinsics(const json& j) {
  sim::CameraIntrinsics k;
  k.width = Number<int>(j, "width");
  k.height = Number<int>(j, "height");
  if (k.width <= 0 || k.height <= 0 || k.width > 8192 || k.height > 8192)
    throw BridgeError("frame size " + std::to_string(k.width) + "x" + std::to_string(k.height) +
                      " is not plausible");
  k.fx = Number<double>(j, "fx");
  k.fy = Number<double>(j, "fy");
  k.cx = Number<double>(j, "cx");
  k.cy = Number<double>(j, "cy");
  return k;
}

json EncodeFrame(const RgbdFrame& f) {
  std::vector<uint8_t> depth(f.depth.size() * 2);
  for (std::size_t i = 0; i < f.depth.size(); ++i) {  // little-endian on the wire
    depth[2 * i] = static_cast<uint8_t>(f.depth[i] & 0xff);
    depth[2 * i + 1] = static_cast<uint8_t>(f.depth[i] >> 8);
  }
  json j = EncodeIntrinsics(f.intrinsics);
  j.update({{"camera", f.camera},
            {"stamp", f.stamp},
            {"extrinsics", EncodePose(f.extrinsics)},
            {"rgb", json::binary(f.rgb)},
            {"depth", json::binary(std::move(depth))}});
  return j;
}

RgbdFrame DecodeFrame(const json& j) {
  RgbdFrame f;
  f.camera = String(j, "camera");
  f.stamp = Number<double>(j, "stamp");
  f.intrinsics = DecodeIntrinsics(j);
  const auto& k = f.intrinsics;
  f.extrinsics = DecodePose(Field(j, "extrinsics"));
  const std::size_t pixels = std::size_t(k.width) * k.height;
  const auto& rgb = Binary(j, "rgb", pixels * 3);
  f.rgb.assign(rgb.begin(), rgb.end());
  const auto& depth = Binary(j, "depth", pixels * 2);
  f.depth.resize(pixels);
  for (std::size_t i = 0; i < pixels; ++i)
    f.depth[i] = static_cast<uint16_t>(depth[2 * i] | (depth[2 * i + 1] << 8));
  return f;
}

json Ok(json reply = json::object()) {
  reply["ok"] = true;
  return reply;
}

// Constant-time comparison, so a wrong token cannot be found a character at a time.
bool SameToken(const std::string& a, const std::string& b) {
  unsigned char diff = a.size() != b.size();
  for (std::size_t i = 0; i < std::min(a.size(), b.size()); ++i) diff |= a[i] ^ b[i];
  return diff == 0;
}

}  // namespace

bool IsLoopback(const std::string& host) {
  return host == "127.0.0.1" || host == "localhost" || host == "::1" || host.rfind("127.", 0) == 0;
}

json EncodeObservation(const Observation& o) {
  json frames = json::array();
  for (const auto& f : o.frames) frames.push_back(EncodeFrame(f));
  return {{"stamp", o.stamp},
          {"q", std::vector<double>(o.q.data(), o.q.data() + sim::kArmDof)},
          {"qd", std::vector<double>(o.qd.data(), o.qd.data() + sim::kArmDof)},
          {"gripper_width", o.gripper_width},
          {"ee", EncodePose(o.ee)},
          {"frames", std::move(frames)}};
}

Observation DecodeObservation(const json& j) {
  Observation o;
  o.stamp = Number<double>(j, "stamp");
  o.q = Vector<sim::kArmDof>(j, "q");
  o.qd = Vector<sim::kArmDof>(j, "qd");
  o.gripper_width = Number<double>(j, "gripper_width");
  o.ee = DecodePose(Field(j, "ee"));
  if (!o.q.allFinite() || !o.qd.allFinite() || !std::isfinite(o.gripper_width))
    throw BridgeError("observation has non-finite joint values");
  const json& frames = Field(j, "frames");
  if (!frames.is_array()) throw BridgeError("field 'frames' is not a list");
  for (const auto& f : frames) o.frames.push_back(DecodeFrame(f));
  return o;
}

json EncodeTargets(const sim::JointTargets& t) {
  return {{"arm", std::vector<double>(t.arm.data(), t.arm.data() + sim::kArmDof)},
          {"finger", t.finger},
          {"closure", t.closure}};
}

sim::JointTargets DecodeTargets(const json& j) {
  sim::JointTargets t;
  t.arm = Vector<sim::kArmDof>(j, "arm");
  t.finger = Number<double>(j, "finger");
  t.closure = Number<double>(j, "closure");
  if (!t.arm.allFinite() || !std::isfinite(t.finger) || !std::isfinite(t.closure))
    throw BridgeError("joint targets are not finite");
  return t;
}

json EncodeOperatorInput(const OperatorInput& in) {
  json j = {{"kind", ToString(in.kind)}, {"think", in.think}};
  if (in.kind == OperatorInput::Kind::kAction) {
    if (in.action.mode == sim::ActionMode::kDiscrete)
      j["action"] = {{"discrete", in.action.index}};
    else
      j["action"] = {{"continuous", in.action.value}};
  }
  return j;
}

OperatorInput DecodeOperatorInput(const json& j) {
  OperatorInput in;
  const std::string kind = String(j, "kind");
  in.think = j.value("think", 0.0);
  if (kind == "idle")
    in.kind = OperatorInput::Kind::kIdle;
  else if (kind == "done")
    in.kind = OperatorInput::Kind::kDone;
  else if (kind == "quit")
    in.kind = OperatorInput::Kind::kQuit;
  else if (kind == "action")
    in.kind = OperatorInput::Kind::kAction;
  else
    throw BridgeError("operator input kind '" + kind + "' is not action/idle/done/quit");
  if (in.kind != OperatorInput::Kind::kAction) return in;
  const json& a = Field(j, "action");
  if (a.contains("discrete")) {
    in.action = sim::Action::Discrete(Number<int>(a, "discrete"));
    if (in.action.index < 0 || in.action.index >= sim::kDiscreteActions)
      throw BridgeError("discrete action " + std::to_string(in.action.index) + " is not in 0..13");
  } else {
    const auto v = Vector<sim::kContinuousActionDim>(a, "continuous");
    if (!v.allFinite()) throw BridgeError("continuous action is not finite");
    std::array<double, sim::kContinuousActionDim> value{};
    std::copy(v.data(), v.data() + sim::kContinuousActionDim, value.begin());
    in.action = sim::Action::Continuous(value);
  }
  return in;
}

// ---------------------------------------------------------------------------------------------

struct BridgeServer::Zmq {
  zmq::context_t context{1};
  zmq::socket_t socket{context, zmq::socket_type::rep};
};

BridgeServer::BridgeServer(Robot& robot, const ServeOptions& options)
    : robot_(robot), options_(options), zmq_(std::make_unique<Zmq>()) {
  if (!IsLoopback(options.bind) && options.token.empty())
    throw core::ConfigError("reality serve", "token",
                            "a shared token: listening on " + options.bind +
                                " (not loopback) without one would let anyone move the robot");
  if (options.port <= 0 || options.port > 65535)
    throw core::ConfigError("reality serve", "port",
                            "a TCP port in 1..65535, got " + std::to_string(options.port));
  endpoint_ = "tcp://" + options.bind + ":" + std::to_string(options.port);
  zmq_->socket.set(zmq::sockopt::linger, 0);
  zmq_->socket.set(zmq::sockopt::rcvtimeo, 100);
  try {
    zmq_->socket.bind(endpoint_);
  } catch (const zmq::error_t& e) {
    throw BridgeError("cannot listen on " + endpoint_ + ": " + e.what());
  }
}

BridgeServer::~BridgeServer() = default;

json BridgeServer::Handle(const json& request) {
  try {
    if (!request.is_object()) throw BridgeError("request is not a map");
    if (!options_.token.empty()) {
      const auto it = request.find("token");
      if (it == request.end() || !it->is_string() || !SameToken(*it, options_.token))
        return {{"ok", false}, {"error", "unauthorized: wrong or missing token"}};
    }
    const std::string op = String(request, "op");
    if (op == "hello") {
      const RobotInfo info = robot_.Info();
      return Ok({{"protocol", kBridgeProtocol},
                 {"info",
                  {{"name", info.name},
                   {"robot", info.robot},
                   {"control_period", info.control_period},
                   {"cameras", info.cameras},
                   {"has_success_oracle", info.has_success_oracle},
                   {"can_scan", info.can_scan},
                   {"has_operator", info.has_operator}}}});
    }
    if (op == "observe") {
      const bool frames = request.value("frames", true);
      return Ok({{"observation", EncodeObservation(robot_.Observe(frames))}});
    }
    if (op == "act") {
      robot_.SendTargets(DecodeTargets(Field(request, "targets")));
      return Ok();
    }
    if (op == "reset") {
      ResetRequest r;
      r.seed = Number<uint64_t>(request, "seed");
      r.level = Number<int>(request, "level");
      return Ok({{"observation", EncodeObservation(robot_.Reset(r))}});
    }
    if (op == "success") return Ok({{"success", ToString(robot_.QuerySuccess())}});
    if (op == "capture") {
      CaptureRequest r;
      r.pose = DecodePose(Field(request, "pose"));
      r.intrinsics = DecodeIntrinsics(Field(request, "intrinsics"));
      return Ok({{"frame", EncodeFrame(robot_.Capture(r))}});
    }
    if (op == "operator") return Ok({{"input", EncodeOperatorInput(robot_.AskOperator())}});
    throw BridgeError("unknown op '" + op +
                      "' (hello, observe, act, reset, success, capture, operator)");
  } catch (const std::exception& e) {
    return {{"ok", false}, {"error", e.what()}};
  }
}

void BridgeServer::Run(const std::atomic<bool>& stop) {
  spdlog::info("bridge: serving {} on {}", robot_.Info().name, endpoint_);
  while (!stop.load()) {
    zmq::message_t message;
    zmq::recv_result_t got;
    try {
      got = zmq_->socket.recv(message);
    } catch (const zmq::error_t& e) {
      if (e.num() == EINTR) continue;
      throw BridgeError("bridge server on " + endpoint_ + ": " + e.what());
    }
    if (!got) continue;  // timeout: check `stop`
    json reply;
    try {
      const auto* bytes = static_cast<const uint8_t*>(message.data());
      reply = Handle(json::from_msgpack(bytes, bytes + message.size()));
    } catch (const json::exception& e) {
      reply = {{"ok", false}, {"error", std::string("request is not MessagePack: ") + e.what()}};
    }
    const std::vector<uint8_t> out = json::to_msgpack(reply);
    zmq_->socket.send(zmq::buffer(out), zmq::send_flags::none);
    ++requests_;
  }
  spdlog::info("bridge: stopped after {} requests", requests_);
}

// ---------------------------------------------------------------------------------------------

struct BridgeClient::Zmq {
  zmq::context_t context{1};
  std::unique_ptr<zmq::socket_t> socket;
};

BridgeClient::BridgeClient(const ClientOptions& options)
    : options_(options), zmq_(std::make_unique<Zmq>()) {
  Connect();
}

BridgeClient::~BridgeClient() = default;

void BridgeClient::Connect() {
  // A REQ socket that missed a reply cannot send again: start over with a fresh one.
  zmq_->socket = std::make_unique<zmq::socket_t>(zmq_->context, zmq::socket_type::req);
  const int ms = static_cast<int>(options_.timeout.count());
  zmq_->socket->set(zmq::sockopt::linger, 0);
  zmq_->socket->set(zmq::sockopt::rcvtimeo, ms);
  zmq_->socket->set(zmq::sockopt::sndtimeo, ms);
  try {
    zmq_->socket->connect(options_.address);
  } catch (const zmq::error_t& e) {
    throw BridgeError("cannot connect to " + options_.address + ": " + e.what());
  }
}

json BridgeClient::Call(json request) {
  const std::string op = request.value("op", "?");
  if (!options_.token.empty()) request["token"] = options_.token;
  const std::vector<uint8_t> bytes = json::to_msgpack(request);
  {
    zmq::message_t reply;
    bool answered = false;
    try {
      answered = zmq_->socket->send(zmq::buffer(bytes), zmq::send_flags::none) &&
                 zmq_->socket->recv(reply);
    } catch (const zmq::error_t& e) {
      Connect();
      throw BridgeError("bridge " + options_.address + ", request '" + op + "': " + e.what());
    }
    if (!answered) {
      Connect();  // so that the next request reaches a restarted server
      throw BridgeError("no reply from " + options_.address + " to '" + op + "' within " +
                        std::to_string(options_.timeout.count()) +
                        " ms: is `twinforge reality serve` (or the robot's driver) running?");
    }
    json decoded;
    try {
      const auto* data = static_cast<const uint8_t*>(reply.data());
      decoded = json::from_msgpack(data, data + reply.size());
    } catch (const json::exception& e) {
      throw BridgeError("reply from " + options_.address + " to '" + op +
                        "' is not MessagePack: " + e.what());
    }
    if (!decoded.is_object() || !decoded.value("ok", false))
      throw BridgeError(options_.address + " refused '" + op + "': " +
                        (decoded.is_object() ? decoded.value("error", "no reason given")
                                             : std::string("malformed reply")));
    return decoded;
  }
}

RobotInfo BridgeClient::Info() {
  if (info_) return *info_;
  const json reply = Call({{"op", "hello"}, {"protocol", kBridgeProtocol}});
  const int protocol = Number<int>(reply, "protocol");
  if (protocol != kBridgeProtocol)
    throw BridgeError(options_.address + " speaks bridge protocol " + std::to_string(protocol) +
                      ", this client " + std::to_string(kBridgeProtocol));
  const json& j = Field(reply, "info");
  RobotInfo info;
  info.name = String(j, "name");
  info.robot = String(j, "robot");
  info.control_period = Number<double>(j, "control_period");
  for (const auto& c : Field(j, "cameras"))
    info.cameras.push_back(c.is_string() ? c.get<std::string>() : "?");
  info.has_success_oracle = j.value("has_success_oracle", false);
  info.can_scan = j.value("can_scan", false);
  info.has_operator = j.value("has_operator", false);
  info_ = info;
  return info;
}

Observation BridgeClient::Observe(bool with_frames) {
  return DecodeObservation(
      Field(Call({{"op", "observe"}, {"frames", with_frames}}), "observation"));
}

void BridgeClient::SendTargets(const sim::JointTargets& targets) {
  Call({{"op", "act"}, {"targets", EncodeTargets(targets)}});
}

Observation BridgeClient::Reset(const ResetRequest& request) {
  return DecodeObservation(Field(
      Call({{"op", "reset"}, {"seed", request.seed}, {"level", request.level}}), "observation"));
}

SuccessAnswer BridgeClient::QuerySuccess() {
  const std::string s = String(Call({{"op", "success"}}), "success");
  if (s == "success") return SuccessAnswer::kSuccess;
  if (s == "failure") return SuccessAnswer::kFailure;
  return SuccessAnswer::kUnknown;
}

RgbdFrame BridgeClient::Capture(const CaptureRequest& request) {
  return DecodeFrame(Field(Call({{"op", "capture"},
                                 {"pose", EncodePose(request.pose)},
                                 {"intrinsics", EncodeIntrinsics(request.intrinsics)}}),
                           "frame"));
}

OperatorInput BridgeClient::AskOperator() {
  return DecodeOperatorInput(Field(Call({{"op", "operator"}}), "input"));
}

}  // namespace twinforge::reality
