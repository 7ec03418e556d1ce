#include "reality/bridge.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <thread>
#include <zmq.hpp>

#include "reality/proxy_reality.h"
#include "reality/scan.h"
#include "reality/test_support.h"

namespace twinforge::reality {
namespace {

using namespace std::chrono_literals;

using testing::Client;
using testing::Served;
using testing::TestPort;

TEST(Bridge, ObservationSurvivesTheWireEncoding) {
  ProxyReality proxy(ResolveWorldDir("open_drawer"));
  const Observation o = proxy.Observe(true);
  const std::vector<uint8_t> wire = nlohmann::json::to_msgpack(EncodeObservation(o));
  const Observation back = DecodeObservation(nlohmann::json::from_msgpack(wire));
  EXPECT_EQ(back.q, o.q);
  EXPECT_EQ(back.qd, o.qd);
  EXPECT_EQ(back.gripper_width, o.gripper_width);
  EXPECT_LT((back.ee.translation - o.ee.translation).norm(), 1e-12);
  ASSERT_EQ(back.frames.size(), 1u);
  EXPECT_EQ(back.frames[0].depth, o.frames[0].depth);
  EXPECT_EQ(back.frames[0].rgb, o.frames[0].rgb);
  EXPECT_EQ(back.frames[0].intrinsics.fx, o.frames[0].intrinsics.fx);
}

// Every message over loopback: hello, reset, observe (with and without frames), act, success.
TEST(Bridge, EveryMessageRoundTrips) {
  const int port = TestPort(1);
  Served served(port);
  BridgeClient client(Client(port));
  const RobotInfo info = client.Info();
  EXPECT_EQ(info.name, "proxy:open_drawer");
  EXPECT_EQ(info.robot, "panda");
  EXPECT_NEAR(info.control_period, 0.1, 1e-12);
  EXPECT_TRUE(info.has_success_oracle);

  const Observation start = client.Reset({7, 1});
  ASSERT_EQ(start.frames.size(), 1u);
  const auto& k = start.frames[0].intrinsics;
  EXPECT_EQ(start.frames[0].depth.size(), std::size_t(k.width) * k.height);
  EXPECT_EQ(client.Observe(false).frames.size(), 0u);

  // Three 3 cm moves up through the client (safety filter + the twin's IK) lift the tool; the
  // proxy's softer, lagging controller covers less than the twin's ~9 cm.
  ActionClient actions(client, sim::ActionLimits{});
  Observation o = client.Observe(false);
  for (int i = 0; i < 3; ++i) {
    actions.Act(sim::Action::Discrete(5), o);  // -z in the tool frame: up, tool pointing down
    o = client.Observe(false);
  }
  EXPECT_GT(o.ee.translation.z() - start.ee.translation.z(), 0.045);
  EXPECT_GT(o.stamp, start.stamp);
  EXPECT_EQ(client.QuerySuccess(), SuccessAnswer::kFailure);

  // A scan frame from a requested pose, at requested intrinsics.
  EXPECT_TRUE(info.can_scan);
  ScanOptions scan;
  scan.width = 64;
  scan.height = 48;
  const core::Pose pose = start.frames[0].extrinsics;
  const RgbdFrame frame = client.Capture({pose, ScanIntrinsics(scan)});
  EXPECT_EQ(frame.intrinsics.width, 64);
  EXPECT_LT((frame.extrinsics.translation - pose.translation).norm(), 1e-12);
  ASSERT_EQ(frame.depth.size(), 64u * 48u);
  EXPECT_GT(std::count_if(frame.depth.begin(), frame.depth.end(), [](uint16_t d) { return d > 0; }),
            64 * 48 / 2);

  // The world's own operator presses a key.
  EXPECT_TRUE(info.has_operator);
  const OperatorInput in = client.AskOperator();
  EXPECT_EQ(in.kind, OperatorInput::Kind::kAction);
  EXPECT_GT(in.think, 0);
}

TEST(Bridge, OperatorInputSurvivesTheWireEncoding) {
  OperatorInput in;
  in.kind = OperatorInput::Kind::kAction;
  in.action = sim::Action::Continuous({0.01, -0.02, 0.003, 0.1, -0.1, 0.05, 1});
  in.think = 1.25;
  const auto wire = nlohmann::json::to_msgpack(EncodeOperatorInput(in));
  const OperatorInput back = DecodeOperatorInput(nlohmann::json::from_msgpack(wire));
  EXPECT_EQ(back.kind, in.kind);
  EXPECT_EQ(back.action.mode, sim::ActionMode::kContinuous);
  EXPECT_EQ(back.action.value, in.action.value);
  EXPECT_EQ(back.think, 1.25);
  in.action = sim::Action::Discrete(13);
  EXPECT_EQ(DecodeOperatorInput(EncodeOperatorInput(in)).action.index, 13);
  EXPECT_THROW(DecodeOperatorInput({{"kind", "action"}, {"action", {{"discrete", 14}}}}),
               BridgeError);
  EXPECT_THROW(DecodeOperatorInput({{"kind", "dance"}}), BridgeError);
}

// A killed server: the client gets an error naming the address within its timeout, and talks
// to the server again once it is back.
TEST(Bridge, DeadServerGivesAnErrorWithinTheTimeout) {
  const int port = TestPort(2);
  auto served = std::make_unique<Served>(port);
  BridgeClient client(Client(port, 400ms));
  client.Observe(false);
  served.reset();  // the server dies
  const auto start = std::chrono::steady_clock::now();
  try {
    client.Observe(false);
    FAIL() << "no error from a dead server";
  } catch (const BridgeError& e) {
    EXPECT_NE(std::string(e.what()).find("127.0.0.1:" + std::to_string(port)), std::string::npos)
        << e.what();
  }
  EXPECT_LT(std::chrono::steady_clock::now() - start, 400ms + 300ms);
  served = std::make_unique<Served>(port);
  EXPECT_NO_THROW(client.Observe(false));
}

TEST(Bridge, TokenIsRequiredOffLoopbackAndChecked) {
  ProxyReality proxy(ResolveWorldDir("open_drawer"));
  EXPECT_THROW(BridgeServer(proxy, {.bind = "0.0.0.0", .port = TestPort(3), .token = ""}),
               core::ConfigError);
  const int port = TestPort(4);
  Served served(port, "s3cret");
  ClientOptions options = Client(port, 2000ms);
  BridgeClient anonymous(options);
  try {
    anonymous.Observe(false);
    FAIL() << "served without the token";
  } catch (const BridgeError& e) {
    EXPECT_NE(std::string(e.what()).find("unauthorized"), std::string::npos) << e.what();
  }
  options.token = "s3cret";
  BridgeClient member(options);
  EXPECT_NO_THROW(member.Observe(false));
}

// Garbage and bad values get an error reply (the server stays up), NaN targets included.
TEST(Bridge, BadRequestsAreRefusedWithAReason) {
  const int port = TestPort(5);
  Served served(port);
  zmq::context_t context;
  zmq::socket_t raw(context, zmq::socket_type::req);
  raw.set(zmq::sockopt::rcvtimeo, 3000);
  raw.connect("tcp://127.0.0.1:" + std::to_string(port));
  raw.send(zmq::str_buffer("not msgpack \xc1"), zmq::send_flags::none);
  zmq::message_t reply;
  ASSERT_TRUE(raw.recv(reply));
  const auto* bytes = static_cast<const uint8_t*>(reply.data());
  const auto j = nlohmann::json::from_msgpack(bytes, bytes + reply.size());
  EXPECT_FALSE(j["ok"].get<bool>());

  BridgeClient client(Client(port));
  sim::JointTargets nan;
  nan.arm.setConstant(std::nan(""));
  try {
    client.SendTargets(nan);
    FAIL() << "NaN targets accepted";
  } catch (const BridgeError& e) {
    EXPECT_NE(std::string(e.what()).find("not finite"), std::string::npos) << e.what();
  }
  EXPECT_NO_THROW(client.Observe(false));
}

}  // namespace
}  // namespace twinforge::reality
