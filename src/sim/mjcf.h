// Assembling one MJCF model from a robot file, a scene (twin) file and generated extras.
#pragma once

#include <filesystem>
#include <string>

#include "core/se3.h"

namespace twinforge::sim {

struct MjcfParts {
  std::filesystem::path robot;  // robot MJCF; its worldbody goes under a mount body
  core::Pose robot_mount;       // pose of the robot base in the world
  std::filesystem::path scene;  // scene MJCF (table, objects, articulations)
  std::string extra_worldbody;  // generated bodies (e.g. distractors), inserted verbatim
  double timestep = 0.005;
};

// Merges the parts into one MJCF document: compiler/option from twinforge, defaults, assets,
// bodies, actuators, contacts, equalities, tendons and sensors from both files. Relative asset
// file paths are made absolute so the result compiles from memory. Scene files must keep their
// defaults in named classes (two files cannot both set the unnamed top-level default). A scene
// may <include file="..."/> another scene (path relative to it) at its top level.
// Throws ConfigError naming the file if either is not well-formed MJCF.
std::string AssembleMjcf(const MjcfParts& parts);

// "x y z ..." at full double precision, for MJCF attributes.
std::string FormatNumbers(const double* v, int n);

}  // namespace twinforge::sim
