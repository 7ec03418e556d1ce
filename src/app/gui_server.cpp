#include "app/gui_server.h"

#include <pthread.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <map>
#include <mutex>
#include <thread>

#include "core/error.h"
#include "real2sim/twin_edit.h"

// Last: it brings <resolv.h>, whose `_res` macro breaks Eigen headers included after it.
#include <httplib.h>

namespace twinforge::app {

namespace {

// Content types carry a charset. Besides being right, that keeps cpp-httplib from compressing
// them: Debian's build prefers Brotli at its slowest setting, which took 6 s for a 4 MB scan
// that loopback moves in 0.07 s.
constexpr const char* kJson = "application/json; charset=utf-8";

void Reply(httplib::Response& res, int status, const core::Json& body) {
  res.status = status;
  // An error message may quote bytes that are not UTF-8 (a query string, a cut-off name).
  res.set_content(body.dump(-1, ' ', false, core::Json::error_handler_t::replace), kJson);
}

// A request for something that does not exist (404), as against a refused edit (400).
struct NotFound : core::Error {
  using core::Error::Error;
};

// The built page's files (index.html, app.js, style.css...), read once.
void ServePage(httplib::Server& server, const std::filesystem::path& web) {
  static const std::map<std::string, std::string> types = {
      {".html", "text/html; charset=utf-8"},
      {".js", "application/javascript; charset=utf-8"},
      {".css", "text/css; charset=utf-8"},
      {".svg", "image/svg+xml; charset=utf-8"},
      {".png", "image/png"}};
  for (const auto& entry : std::filesystem::directory_iterator(web)) {
    const auto type = types.find(entry.path().extension().string());
    if (!entry.is_regular_file() || type == types.end()) continue;
    std::ifstream in(entry.path(), std::ios::binary);
    auto body = std::make_shared<std::string>(std::istreambuf_iterator<char>(in),
                                              std::istreambuf_iterator<char>());
    const std::string name = entry.path().filename().string();
    auto handler = [body, content_type = type->second](const httplib::Request&,
                                                       httplib::Response& res) {
      res.set_content(*body, content_type.c_str());
    };
    server.Get("/" + name, handler);
    if (name == "index.html") server.Get("/", handler);
  }
}

// Runs `work` under the session lock and turns what it throws into the API's error replies:
// a refused edit is the user's to fix (400), a missing file or part is 404, the rest 500.
template <class Work>
void Handle(std::mutex& lock, httplib::Response& res, Work&& work) {
  try {
    std::lock_guard<std::mutex> guard(lock);
    Reply(res, 200, work());
  } catch (const NotFound& e) {
    Reply(res, 404, {{"error", e.what()}});
  } catch (const core::ConfigError& e) {
    Reply(res, 400, {{"error", e.what()}});
  } catch (const std::exception& e) {
    spdlog::error("gui: {}", e.what());
    Reply(res, 500, {{"error", e.what()}});
  }
}

// Edits come as JSON: a browser cannot send that cross-site without asking first (a CORS
// preflight this server never grants), so another web page cannot edit the twin.
void RequireJson(const httplib::Request& req) {
  if (req.get_header_value("Content-Type").rfind("application/json", 0) != 0)
    throw core::ConfigError("request to " + req.path, "Content-Type", "application/json");
}

core::Json ParseBody(const httplib::Request& req) {
  RequireJson(req);
  core::Json body = core::Json::parse(req.body, nullptr, false);
  if (body.is_discarded() || !body.is_object())
    throw core::ConfigError("request to " + req.path, "", "the body is not a JSON object");
  return body;
}

}  // namespace

std::filesystem::path ResolveWebDir(const std::filesystem::path& requested) {
  std::filesystem::path dir = requested;
  if (dir.empty()) {
    const char* env = std::getenv("TWINFORGE_WEB_DIR");
    dir = env && *env ? env : TWINFORGE_WEB_DIR;
  }
  if (!std::filesystem::is_regular_file(dir / "index.html"))
    throw core::IoError(
        "the twin editor's page is not built: no " + (dir / "index.html").string() +
        " (scripts/setup.sh installs its npm packages, scripts/build.sh bundles it)");
  return dir;
}

void ServeTwinEditor(const GuiOptions& options) {
  const std::filesystem::path web = ResolveWebDir(options.web);
  real2sim::TwinEditSession session(options.twin);
  std::mutex lock;

  httplib::Server server;
  ServePage(server, web);
  server.Get("/api/twin", [&](const httplib::Request&, httplib::Response& res) {
    Handle(lock, res, [&] { return session.State(); });
  });
  server.Get("/api/scan", [&](const httplib::Request&, httplib::Response& res) {
    Handle(lock, res, [&] {
      if (!std::filesystem::exists(session.dir() / "scan.ply"))
        throw NotFound("the twin has no scan.ply");
      return session.ScanJson();
    });
  });
  server.Get("/api/part", [&](const httplib::Request& req, httplib::Response& res) {
    Handle(lock, res, [&] {
      const std::string name = req.get_param_value("name");
      const auto& parts = session.spec().parts;
      if (std::none_of(parts.begin(), parts.end(), [&](const auto& p) { return p.name == name; }))
        throw NotFound("the twin has no part named '" + name + "'");
      return session.PartMeshJson(name);
    });
  });
  server.Post("/api/spec", [&](const httplib::Request& req, httplib::Response& res) {
    Handle(lock, res, [&] {
      const core::Json body = ParseBody(req);
      if (!body.contains("spec"))
        throw core::ConfigError("request to /api/spec", "spec", "the whole twin spec");
      session.Propose(body["spec"]);
      spdlog::info("gui: edit accepted ({} parts, {} joints, {} sites)",
                   session.spec().parts.size(), session.spec().joints.size(),
                   session.spec().sites.size());
      return session.State();
    });
  });
  server.Post("/api/undo", [&](const httplib::Request& req, httplib::Response& res) {
    Handle(lock, res, [&] {
      RequireJson(req);
      session.Undo();
      return session.State();
    });
  });
  server.Post("/api/save", [&](const httplib::Request& req, httplib::Response& res) {
    Handle(lock, res, [&] {
      RequireJson(req);
      const auto path = session.Save();
      spdlog::info("gui: saved {}", path.string());
      return core::Json{{"saved", path.string()}, {"backup", path.string() + ".bak"}};
    });
  });
  server.Post("/api/export", [&](const httplib::Request& req, httplib::Response& res) {
    Handle(lock, res, [&] {
      RequireJson(req);
      core::Json exported = session.Export();
      spdlog::info("gui: exported {}", exported["scene"].get<std::string>());
      exported["state"] = session.State();
      return exported;
    });
  });

  // SIGINT/SIGTERM stop the server from a thread of their own; the server's threads inherit the
  // blocked mask, so the signal reaches only that thread.
  sigset_t stop_signals;
  sigemptyset(&stop_signals);
  sigaddset(&stop_signals, SIGINT);
  sigaddset(&stop_signals, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &stop_signals, nullptr);

  const std::string host = "127.0.0.1";
  const int port = options.port == 0                         ? server.bind_to_any_port(host)
                   : server.bind_to_port(host, options.port) ? options.port
                                                             : -1;
  if (port <= 0)
    throw core::IoError("cannot listen on " + host + ":" + std::to_string(options.port) +
                        " (in use? --port 0 picks a free one)");
  std::atomic<bool> listening_done = false;
  std::thread stopper([&] {
    int signal = 0;
    sigwait(&stop_signals, &signal);
    // A signal right after the bind: wait until the server runs, or stop() would do nothing.
    while (!server.is_running() && !listening_done)
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    server.stop();
  });
  std::cout << "gui: serving http://" << host << ":" << port << "/ (twin " << session.dir().string()
            << "; Ctrl+C stops)" << std::endl;
  const bool listened = server.listen_after_bind();
  listening_done = true;
  if (!listened) pthread_kill(stopper.native_handle(), SIGTERM);
  stopper.join();
  if (session.dirty()) spdlog::warn("gui: stopped with unsaved edits (twin.yaml is as last saved)");
  if (!listened)
    throw core::IoError("the editor's server on port " + std::to_string(port) + " failed");
}

}  // namespace twinforge::app
