// An editing session on one twin directory: what the twin editor (`twinforge gui`) does to a
// twin, without the HTTP. Every proposed spec goes through the same checks as the CLI's
// twin.yaml; accepted specs stack up for undo; saving writes twin.yaml atomically and keeps the
// previous one as twin.yaml.bak; exporting writes the MuJoCo scene and lists what it compiled to.
// Meshes and geoms are returned as JSON a browser can draw directly (flat arrays).
#pragma once

#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "core/config.h"
#include "real2sim/export.h"
#include "real2sim/twin_spec.h"

namespace twinforge::real2sim {

class TwinEditSession {
 public:
  // Opens `twin_dir/twin.yaml`. Throws IoError/ConfigError naming the file if it is missing or
  // invalid.
  explicit TwinEditSession(std::filesystem::path twin_dir);

  const TwinSpec& spec() const { return spec_; }
  const std::filesystem::path& dir() const { return dir_; }
  bool can_undo() const { return !undo_.empty(); }
  bool dirty() const;  // the current spec differs from the twin.yaml on disk

  // {"name", "dir", "spec", "can_undo", "dirty"}.
  core::Json State() const;

  // Replaces the spec with `proposed` (the whole spec, as JSON) if it passes twin.yaml's checks;
  // the previous spec goes on the undo stack. Throws ConfigError naming "twin.yaml (edit)" and
  // the field (e.g. "sites[2].name: a second site named 'grip'", or a part cut down to nothing);
  // the spec is then unchanged.
  void Propose(const core::Json& proposed);
  // Back to the spec before the last accepted edit. Throws ConfigError if there is none.
  void Undo();

  // Writes twin.yaml atomically if the spec changed. The first save of a session keeps the file
  // it opened as twin.yaml.bak; later saves leave that backup alone. Returns the path.
  std::filesystem::path Save();

  // Saves if dirty, then writes scene.xml with the cameras the previous export had, compiles it
  // with the robot, and returns {"scene", "boxes": {part: n}, "geoms": [...], "meshes": [...]}:
  // each geom's world pose at the model's rest state (pos, quat w-first, MuJoCo size, rgba,
  // type, body, collision, robot, mesh index into "meshes" or -1); meshes in their geom's frame.
  core::Json Export(const ExportOptions& options = {});

  // A part's mesh with its cuts applied: {"name", "positions", "colors" (0..1), "indices"}, only
  // the vertices its triangles use. Throws ConfigError if there is no such part.
  core::Json PartMeshJson(const std::string& part);
  // The fused scan (scan.ply) as points, every k-th vertex so that at most `max_points` remain:
  // {"positions", "colors"}. Throws IoError if the twin has no scan.ply.
  core::Json ScanJson(int max_points = 80000);

 private:
  const Mesh& SourceMesh(const std::string& relative);
  const Mesh& CutPart(const PartSpec& part);  // its mesh with its cuts applied (cached)

  std::filesystem::path dir_;
  TwinSpec spec_;
  core::Json saved_;  // the spec on disk, as JSON
  std::vector<TwinSpec> undo_;
  bool backed_up_ = false;              // twin.yaml.bak holds the file the session opened
  std::map<std::string, Mesh> meshes_;  // mesh files read so far, by path in the twin
  std::map<std::string, Mesh> cut_;     // cut meshes, by mesh path and cuts
};

// The cameras of an exported scene.xml (name, pose in OpenCV axes, fovy), so a re-export keeps
// them. Empty if the file does not exist; throws ConfigError if it is not well-formed.
std::vector<ExportCamera> ReadSceneCameras(const std::filesystem::path& scene_xml);

}  // namespace twinforge::real2sim
