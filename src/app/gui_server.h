// `twinforge gui`: the twin editor, served on loopback. The page (web/, three.js, bundled at
// build time) talks to a TwinEditSession through a small JSON API:
//   GET  /api/twin            {"name", "dir", "spec", "can_undo", "dirty"}
//   GET  /api/scan            the fused scan as points {"positions", "colors"}
//   GET  /api/part?name=N     a part's mesh with its cuts {"name", "positions", "colors",
//   "indices"} POST /api/spec {"spec"}   an edit: validated as twin.yaml is; the new state, or 400
//   {"error"} POST /api/undo            the state before the last accepted edit POST /api/save
//   twin.yaml written atomically, the previous kept as twin.yaml.bak POST /api/export scene.xml
//   written; the compiled geoms and meshes to draw
// Errors are {"error": message}: 400 for a refused edit, 404 for something missing, 500 else.
#pragma once

#include <filesystem>

namespace twinforge::app {

struct GuiOptions {
  std::filesystem::path twin;  // twin directory (twin.yaml, scan.ply, meshes/)
  int port = 8765;             // 0: any free port
  // The built page (index.html, app.js, style.css); empty: $TWINFORGE_WEB_DIR, else the build's.
  std::filesystem::path web;
};

// The directory the page is served from. Throws IoError saying how to build it if it has no
// index.html.
std::filesystem::path ResolveWebDir(const std::filesystem::path& requested);

// Serves the editor until SIGINT or SIGTERM. Prints "gui: serving http://127.0.0.1:PORT/" once
// listening. Throws IoError if the port cannot be bound, or the twin cannot be opened.
void ServeTwinEditor(const GuiOptions& options);

}  // namespace twinforge::app
