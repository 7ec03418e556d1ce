// From a proposed twin spec to a twin a task can run in: the part that moved between two scans
// cut out and joined to what it moves in, then the task's names put on the parts, joints and
// sites by the task's twin recipe (sim::TwinRecipe), and a task file that points at the twin.
#pragma once

#include <filesystem>
#include <string>

#include "real2sim/articulation.h"
#include "real2sim/segment.h"
#include "sim/task.h"

namespace twinforge::real2sim {

// The part that moved between the two scans, in the first state.
struct MovingPart {
  std::string segment;  // the segment (and proposed part) it moves in
  BoxSpec region;       // the room it takes: an oriented box around what moved, reaching back
                        // into the segment (a drawer's tray) or a panel's thickness (a door)
  Eigen::Vector3d opens = Eigen::Vector3d::UnitX();  // unit: the way its front moves as it opens
  Mesh mesh;  // its surface from both scans (the second sees more of it), in the first state
};

// Finds the moving part of `estimate` among the segments of the first scan, lines the estimate
// up with that segment (SnapToFrame, within `snap` rad; 0: not at all; then RefitMotion), and
// cuts the part's surface out of both scans' meshes. Throws core::Error if no segment holds
// what moved.
MovingPart FindMovingPart(const Segmentation& first, ArticulationEstimate& estimate,
                          const Mesh& first_mesh, const Mesh& second,
                          double snap = 10.0 * M_PI / 180);

// Adds `moving` to `spec` as part `name` (its mesh written to twin_dir/meshes/<name>.ply), cut
// out of its segment's part by a subtract cut, and joined to it by joint `joint` with the
// estimated type, axis and origin. The range starts at the first state (0) and reaches the
// larger of what was seen and a guess from the part's size (a person should check it).
void AddMovingPart(TwinSpec& spec, const MovingPart& moving, const ArticulationEstimate& estimate,
                   const std::string& name, const std::string& joint,
                   const std::filesystem::path& twin_dir);

// Puts the recipe's names on `spec`: each recipe part goes to the unclaimed part of the nearest
// size (fixed or free, mass and friction as the recipe says); each recipe joint to the joint
// whose parent became the recipe's parent (its moving part renamed too); then the sites are
// placed. A part of shape "drawing" becomes its drawing (a file next to `task_file`), posed
// where its segment shows it, with the drawing's sites. Throws ConfigError naming `task_file`
// and the recipe field when the scan has nothing for a part or joint.
void ApplyRecipe(TwinSpec& spec, const sim::TwinRecipe& recipe,
                 const std::filesystem::path& twin_dir, const std::filesystem::path& task_file);

// Writes twin_dir/task.yaml: `task` with its scene replaced by the twin's scene.xml. Returns
// its path.
std::filesystem::path WriteTwinTask(const sim::TaskSpec& task,
                                    const std::filesystem::path& twin_dir);

}  // namespace twinforge::real2sim
