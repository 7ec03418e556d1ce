#include "reality/connect.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <signal.h>
#include <spawn.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstring>
#include <thread>
#include <vector>

#include "core/error.h"
#include "core/log.h"

extern char** environ;

namespace twinforge::reality {

int FreeLoopbackPort() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  if (fd < 0) throw core::IoError("cannot open a socket to find a free port");
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  addr.sin_port = 0;
  socklen_t len = sizeof addr;
  const bool ok = ::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) == 0 &&
                  ::getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len) == 0;
  ::close(fd);
  if (!ok) throw core::IoError("cannot find a free loopback port");
  return ntohs(addr.sin_port);
}

RealityConnection::RealityConnection(const ConnectOptions& options) {
  const std::string prefix = "proxy:";
  if (options.address.rfind(prefix, 0) != 0) {
    if (options.address.rfind("tcp://", 0) != 0)
      throw core::ConfigError("--reality", "address",
                              "tcp://host:port or proxy:WORLD, got '" + options.address + "'");
    address_ = options.address;
    client_ = std::make_unique<BridgeClient>(
        ClientOptions{.address = address_, .timeout = options.timeout, .token = options.token});
    return;
  }
  const std::string world = options.address.substr(prefix.size());
  const int port = FreeLoopbackPort();
  address_ = "tcp://127.0.0.1:" + std::to_string(port);
  std::vector<std::string> args = {"twinforge",
                                   "--log-level",
                                   "warn",
                                   "reality",
                                   "serve",
                                   "--world",
                                   world,
                                   "--port",
                                   std::to_string(port),
                                   "--parent",
                                   std::to_string(::getpid())};
  if (!options.token.empty()) args.insert(args.end(), {"--token", options.token});
  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  pid_t pid = -1;
  const int error =
      posix_spawn(&pid, options.server_binary.c_str(), nullptr, nullptr, argv.data(), environ);
  if (error != 0)
    throw core::IoError("cannot start the proxy reality (" + options.server_binary.string() +
                        "): " + std::strerror(error));
  child_ = pid;
  // Wait for the server to answer (loading a world takes a moment), or for it to die.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  for (;;) {
    int status = 0;
    if (::waitpid(child_, &status, WNOHANG) == child_) {
      child_ = -1;
      throw core::Error("the proxy reality for world '" + world +
                        "' exited before answering (exit status " +
                        std::to_string(WIFEXITED(status) ? WEXITSTATUS(status) : -1) +
                        "); run `twinforge reality serve --world " + world + "` to see why");
    }
    try {
      client_ = std::make_unique<BridgeClient>(ClientOptions{
          .address = address_, .timeout = std::chrono::milliseconds(500), .token = options.token});
      client_->Info();
      break;
    } catch (const BridgeError&) {
      if (std::chrono::steady_clock::now() > deadline) {
        ::kill(child_, SIGKILL);
        ::waitpid(child_, nullptr, 0);
        child_ = -1;
        throw core::Error("the proxy reality for world '" + world + "' did not answer on " +
                          address_ + " within 60 s");
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
  }
  client_ = std::make_unique<BridgeClient>(
      ClientOptions{.address = address_, .timeout = options.timeout, .token = options.token});
  spdlog::info("reality: proxy world '{}' serving on {} (pid {})", world, address_, child_);
}

RealityConnection::~RealityConnection() {
  client_.reset();
  if (child_ > 0) {
    ::kill(child_, SIGTERM);
    int status = 0;
    for (int i = 0; i < 50 && ::waitpid(child_, &status, WNOHANG) == 0; ++i)
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    if (::waitpid(child_, &status, WNOHANG) == 0) {
      ::kill(child_, SIGKILL);
      ::waitpid(child_, &status, 0);
    }
  }
}

}  // namespace twinforge::reality
